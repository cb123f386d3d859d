//! Measurement sets (`vmt-measurements/1`, FORMAT.md §1) and error-motion profile CSVs
//! (FORMAT.md §5): plain structs in SI units, a strict reader and an atomic writer.
//!
//! A measurement set is a directory holding `manifest.toml` and one CSV file per run. CSV header
//! cells are `name[unit]` (unit optional → SI); comment lines start with `#`. Two shapes:
//! a time series (`t` strictly increasing, then `x_cmd` and sensor columns) and a point table
//! (`target`, `run` 1..n, `direction` ±1, optional `t`, sensor columns). The reader rejects what it
//! cannot understand with an error naming the file, the line or key path and what was expected
//! (DESIGN.md §2); the writer writes into a temporary sibling directory and renames it into place,
//! and prints floats with the shortest digits that round-trip, so write → read is bit-exact in SI.

use crate::error::{fmt_num, parse_toml, TomlReader, VmtError};
use crate::units::{parse_header_cell, resolve_unit, Dimension, Unit};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use vmt_sim::effects::EffectName;
use vmt_sim::Axis;

/// The `format` value of a measurement set's manifest.
pub const FORMAT_ID: &str = "vmt-measurements/1";

pub use vmt_sim::procedures::{ProcedureKind as Procedure, RunData};
pub use vmt_sim::sensors::SensorKind;

/// The physical dimension of a sensor kind's column (what units its header may carry).
pub fn kind_dimension(kind: SensorKind) -> Dimension {
    match kind {
        SensorKind::Command
        | SensorKind::EncoderRotary
        | SensorKind::EncoderLinear
        | SensorKind::LaserLinear
        | SensorKind::LaserStraightness
        | SensorKind::LaserVector => Dimension::Length,
        SensorKind::LaserAngular => Dimension::Angle,
        SensorKind::Accelerometer => Dimension::Acceleration,
        SensorKind::MotorForce => Dimension::Force,
        SensorKind::Velocity => Dimension::Velocity,
        SensorKind::Temperature => Dimension::Temperature,
        SensorKind::Pressure => Dimension::Pressure,
        SensorKind::Humidity => Dimension::Ratio,
    }
}

/// One sensor of a measurement set (a `[[sensors]]` entry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// The CSV column that carries it.
    pub name: String,
    /// What it measures.
    pub kind: SensorKind,
    /// The prismatic joint it observes (manifest `axis = "x"`, `"y"` or `"z"`).
    #[serde(with = "vmt_core::axis::letter")]
    pub axis: Axis,
    /// Measuring point on the moving body, axis reference frame, m (default 0, 0, 0).
    pub position: [f64; 3],
    /// Sensitive direction, machine frame (default: along the axis).
    pub direction: [f64; 3],
    /// 1-sigma noise in SI units of the channel, if known (≥ 0; 0 = noise-free).
    pub sigma: Option<f64>,
    /// Optional `closes_loop = true` (encoders only): this encoder is the position loop's feedback
    /// (a linear scale: closed loop; the motor's rotary encoder: semi-closed loop).
    #[serde(default)]
    pub closes_loop: bool,
    /// Accelerometers: one-sided white-noise density ρ (m/s²/√Hz), if known (> 0). Optional manifest key
    /// `noise_density`; `vmt straightness` estimates it from the records when absent.
    #[serde(default)]
    pub noise_density: Option<f64>,
    /// Accelerometers: first-order AC-coupling (high-pass) corner of the sensor (Hz, ≥ 0; 0 or absent =
    /// DC coupled). Optional manifest key `highpass`.
    #[serde(default)]
    pub highpass: Option<f64>,
}

/// One run of a measurement set (a `[[runs]]` entry with its CSV data).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Run {
    /// Unique name, e.g. `iso`.
    pub name: String,
    /// CSV file name, relative to the set's directory.
    pub file: String,
    /// Measurement procedure.
    pub procedure: Procedure,
    /// The axis moved (manifest `axis = "x"`, `"y"` or `"z"`).
    #[serde(with = "vmt_core::axis::letter")]
    pub axis: Axis,
    /// Start, s since the start of the measurement session.
    pub start_time: Option<f64>,
    /// Feed, m/s (constant_velocity, crawl).
    pub feed: Option<f64>,
    /// +1 / −1 for a one-way run.
    pub direction: Option<i8>,
    /// The numbers, SI.
    pub data: RunData,
}

/// A measurement set: manifest plus the runs' data, SI units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasurementSet {
    /// Free text.
    pub description: Option<String>,
    /// Bundled machine name or URDF path relative to the set.
    pub machine: Option<String>,
    /// Present when simulated.
    pub seed: Option<u64>,
    /// The sensors.
    pub sensors: Vec<Sensor>,
    /// The runs.
    pub runs: Vec<Run>,
}

impl MeasurementSet {
    /// The sensor called `name`.
    pub fn sensor(&self, name: &str) -> Option<&Sensor> {
        self.sensors.iter().find(|s| s.name == name)
    }

    /// The run called `name`.
    pub fn run(&self, name: &str) -> Option<&Run> {
        self.runs.iter().find(|r| r.name == name)
    }

    /// The whole seconds the set's times are counted from by the model check: those of its
    /// earliest run start (`start_time`, 0 when absent) when every run starts at [`LARGE_TIME`] or
    /// later (a clock's epoch seconds), else 0, so that a run's start less this origin is exact and
    /// its samples' times keep their stamps' digits ([`MeasurementSet::run_start`]).
    pub fn time_origin(&self) -> f64 {
        let first = self.runs.iter().map(|r| r.start_time.unwrap_or(0.0)).fold(f64::INFINITY, f64::min);
        if first.is_finite() && first >= LARGE_TIME {
            first.floor()
        } else {
            0.0
        }
    }

    /// Run `r`'s start, s from the set's [`MeasurementSet::time_origin`].
    pub fn run_start(&self, r: &Run) -> f64 {
        r.start_time.unwrap_or(0.0) - self.time_origin()
    }

    /// The smallest and largest position of axis `axis` the set measured at: the targets of its point
    /// tables and the commanded positions (`x_cmd`) of its time series; None when it has neither.
    pub fn position_range(&self, axis: Axis) -> Option<(f64, f64)> {
        let positions = self.runs.iter().filter(|r| r.axis == axis).flat_map(|r| match &r.data {
            RunData::PointTable { target, .. } => target.as_slice(),
            RunData::TimeSeries { .. } => r.data.command().unwrap_or(&[]),
        });
        positions.filter(|x| x.is_finite()).fold(None, |acc, &x| match acc {
            None => Some((x, x)),
            Some((lo, hi)) => Some((f64::min(lo, x), f64::max(hi, x))),
        })
    }
}

/// Units of the headers a writer produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum UnitChoice {
    /// No unit suffixes: SI values, bit-exact round trip.
    Si,
    /// Units a metrologist reads: positions (t, target, commands, encoders) in mm, laser and
    /// other lengths in um, angles in urad, velocities in mm/s, temperatures in degC, humidity in
    /// percent, others SI. Values are converted, so a round trip is exact to about 1 ulp only.
    Metrology,
}

/// Column names a time series or point table reserves.
const RESERVED: [&str; 4] = ["t", "target", "run", "direction"];

/// True for `x_cmd`, `y_cmd`, `z_cmd`: the commanded position of an axis (a length column).
pub fn is_command_column(name: &str) -> bool {
    matches!(name, "x_cmd" | "y_cmd" | "z_cmd")
}

// ------------------------------------------------------------------------------------------
// Number formatting and atomic writes.

/// Formats an f64 with the shortest digits that parse back to the same bits: plain for
/// 1e-3 ≤ |x| < 1e16 and 0 (`0.25`, `-0`), scientific otherwise (`4e-9`, `2.8e-5`). Non-finite values are
/// never written (writers validate first).
pub fn fmt_f64(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-3..1e16).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// `x` rounded to `digits` significant decimal digits (the nearest f64 to that decimal).
pub fn round_significant(x: f64, digits: usize) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    format!("{x:.*e}", digits.saturating_sub(1)).parse().unwrap_or(x)
}

/// Formats an f64 as a TOML float (always with `.` or `e`, so it stays a float).
pub fn fmt_toml_f64(x: f64) -> String {
    let s = fmt_f64(x);
    if s.contains(['.', 'e', 'E']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// A TOML string literal (quoted and escaped).
pub fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A fresh hidden sibling path of `path`: `.NAME.tag-PID-N`.
fn sibling(path: &Path, tag: &str) -> PathBuf {
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".to_string());
    let parent = parent_dir(path);
    parent.join(format!(".{name}.{tag}-{}-{n}", std::process::id()))
}

/// The parent directory of `path` ("." for a bare name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Writes `bytes` to `path` and flushes them to disk.
fn write_synced(path: &Path, bytes: &[u8]) -> Result<(), VmtError> {
    let mut f = std::fs::File::create(path).map_err(|e| VmtError::io(path, "writing", e))?;
    f.write_all(bytes).and_then(|_| f.sync_all()).map_err(|e| VmtError::io(path, "writing", e))
}

/// Writes a file atomically: into a temporary sibling, then renamed over `path`, so a reader
/// sees the old file or the new one, never a half-written one. Creates missing parent
/// directories.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> Result<(), VmtError> {
    let parent = parent_dir(path);
    std::fs::create_dir_all(&parent).map_err(|e| VmtError::io(&parent, "creating the directory", e))?;
    let tmp = sibling(path, "tmp");
    if let Err(e) = write_synced(&tmp, bytes) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        VmtError::io(path, "renaming into place", e)
    })
}

// ------------------------------------------------------------------------------------------
// CSV reading.

/// A CSV file split into header cells and rows of trimmed text, with the line of each row.
struct CsvText {
    /// (name, unit symbol) per column.
    header: Vec<(String, Option<String>)>,
    /// (1-based line number, cells).
    rows: Vec<(u64, Vec<String>)>,
}

/// Reads a CSV file of FORMAT.md §1: `#` comment lines, one header line, then rows with as many
/// cells as the header. Duplicate column names are rejected.
/// Most columns a CSV may have (size budget, DESIGN.md §2): a run holds t or the point-table keys,
/// the commands and one column per sensor.
pub const MAX_COLUMNS: usize = 1_000;
/// Most runs (CSV files) of a measurement set (size budget).
pub const MAX_RUNS: usize = 100_000;

fn read_csv_text(path: &Path) -> Result<CsvText, VmtError> {
    let bytes = std::fs::read(path).map_err(|e| VmtError::io(path, "reading", e))?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(true)
        // A UTF-8 byte-order mark (spreadsheet exports) is not part of the first column name.
        .from_reader(bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes.as_slice()));
    let mut header: Option<Vec<(String, Option<String>)>> = None;
    let mut rows: Vec<(u64, Vec<String>)> = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let place = e.position().map(|p| format!("line {}", p.line())).unwrap_or_default();
            VmtError::bad(path, place, format!("malformed CSV: {e}"))
        })?;
        let line = rec.position().map_or(0, |p| p.line());
        match &header {
            None => {
                if rec.len() > MAX_COLUMNS {
                    return Err(VmtError::bad(
                        path,
                        format!("line {line} (header)"),
                        format!("{} columns; the limit is {MAX_COLUMNS}", rec.len()),
                    ));
                }
                let mut cols: Vec<(String, Option<String>)> = Vec::new();
                for cell in rec.iter() {
                    let (name, unit) = parse_header_cell(cell)
                        .map_err(|m| VmtError::bad(path, format!("line {line} (header)"), m.to_string()))?;
                    if cols.iter().any(|(n, _)| *n == name) {
                        return Err(VmtError::bad(
                            path,
                            format!("line {line} (header)"),
                            format!("column `{name}` appears twice"),
                        ));
                    }
                    cols.push((name, unit));
                }
                header = Some(cols);
            }
            Some(h) => {
                if rec.len() != h.len() {
                    return Err(VmtError::bad(
                        path,
                        format!("line {line}"),
                        format!("expected {} cells like the header, got {}", h.len(), rec.len()),
                    ));
                }
                rows.push((line, rec.iter().map(|s| s.to_string()).collect()));
            }
        }
    }
    let header = header.ok_or_else(|| VmtError::bad(path, "", "empty CSV file: expected a header line, then rows"))?;
    if rows.is_empty() {
        return Err(VmtError::bad(path, "", "expected at least one row of numbers after the header"));
    }
    Ok(CsvText { header, rows })
}

impl CsvText {
    fn index(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|(n, _)| n == name)
    }

    /// Column `i` as SI numbers: each cell a finite number, converted from the header's unit,
    /// which must have dimension `dim`.
    fn numbers(&self, path: &Path, i: usize, dim: Dimension) -> Result<Vec<f64>, VmtError> {
        let (name, unit) = &self.header[i];
        let u: Unit = resolve_unit(unit.as_deref(), dim)
            .map_err(|m| VmtError::bad(path, format!("column {name}"), m.to_string()))?;
        self.rows
            .iter()
            .map(|(line, cells)| {
                parse_number(&cells[i])
                    .map(|v| u.to_si(v))
                    .map_err(|m| VmtError::bad(path, format!("line {line}, column {name}"), m.to_string()))
            })
            .collect()
    }

    /// Time column `i` in seconds, and the origin it is counted from: 0, unless its first value is
    /// at least [`LARGE_TIME`] (a clock's epoch seconds: at 1.7 × 10⁹ s an f64 steps by 0.24 µs,
    /// and a stamp's last digits are lost in the sum before any interval is taken). Then the first
    /// value's whole units are subtracted in each cell's decimal text ([`relative_cell`]), so
    /// that every digit written stays in the relative time, and returned in seconds.
    fn times(&self, path: &Path, i: usize) -> Result<(Vec<f64>, f64), VmtError> {
        let t = self.numbers(path, i, Dimension::Time)?;
        if !t.first().is_some_and(|v| v.abs() >= LARGE_TIME) {
            return Ok((t, 0.0));
        }
        let (name, unit) = &self.header[i];
        let u: Unit = resolve_unit(unit.as_deref(), Dimension::Time)
            .map_err(|m| VmtError::bad(path, format!("column {name}"), m.to_string()))?;
        // index: t[0] was read from rows[0] above (so the cell parses), in the file's unit.
        let whole = parse_number(&self.rows[0].1[i]).map_or(0.0, f64::trunc);
        let rel: Vec<f64> = self.rows.iter().map(|(_, cells)| u.to_si(relative_cell(&cells[i], whole))).collect();
        Ok((rel, u.to_si(whole)))
    }

    /// Column `i` as raw numbers with no unit allowed (run numbers, directions).
    fn unitless(&self, path: &Path, i: usize, what: &str) -> Result<Vec<f64>, VmtError> {
        let (name, unit) = &self.header[i];
        if let Some(u) = unit {
            return Err(VmtError::bad(
                path,
                format!("column {name}"),
                format!("`{name}` holds {what} and takes no unit, got `[{u}]`"),
            ));
        }
        self.rows
            .iter()
            .map(|(line, cells)| {
                parse_number(&cells[i])
                    .map_err(|m| VmtError::bad(path, format!("line {line}, column {name}"), m.to_string()))
            })
            .collect()
    }

    fn line(&self, row: usize) -> u64 {
        self.rows[row].0
    }
}

/// Why a CSV cell is not a number (the caller adds the file, line and column).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
enum CellError {
    #[error("expected a number, got an empty cell")]
    Empty,
    #[error("expected a finite number, got `{0}`")]
    NotFinite(String),
    #[error("expected a number, got `{0}`")]
    NotANumber(String),
}

/// Time stamps at least this large, s, are read from their first whole second (the whole part
/// subtracted in each cell's digits, the run's `start_time` grown by it): below it an f64 keeps
/// 0.1 ns, far below any log's stamps.
pub const LARGE_TIME: f64 = 1e6;

/// A number cell (already parsed as finite) minus `whole`, an integer: in its decimal text where
/// it is written as [-]digits[.digits] with at most 18 digits before the point (the integer parts
/// subtracted exactly, the fraction added), else its value minus `whole`.
fn relative_cell(cell: &str, whole: f64) -> f64 {
    let value = || parse_number(cell).map_or(f64::NAN, |v| v - whole);
    let (neg, body) = match cell.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, cell.strip_prefix('+').unwrap_or(cell)),
    };
    let (int, frac) = body.split_once('.').unwrap_or((body, ""));
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    if int.is_empty() || int.len() > 18 || !digits(int) || !digits(frac) || whole.abs() >= 1e18 {
        return value();
    }
    let (Ok(i), Ok(f)) = (int.parse::<i64>(), format!("0.{frac}0").parse::<f64>()) else { return value() };
    let sign = if neg { -1.0 } else { 1.0 };
    // Exact: both are integers below 10¹⁸ and their difference is a stamp's span.
    let ints = (if neg { -i } else { i }) - whole as i64;
    ints as f64 + sign * f
}

/// Parses one CSV cell as a finite number.
fn parse_number(cell: &str) -> Result<f64, CellError> {
    if cell.is_empty() {
        return Err(CellError::Empty);
    }
    match cell.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(CellError::NotFinite(cell.to_string())),
        Err(_) => Err(CellError::NotANumber(cell.to_string())),
    }
}

/// Largest |position| a point table or a `.dat` target may hold, m: the sensors' mounting limit
/// (a machine-tool axis is at most tens of metres long); beyond it a number is a unit or typing slip.
pub const MAX_POSITION: f64 = 100.0;

/// Checks the rows of a point table the same way for every reader (measurement set CSV, `.dat`,
/// writers): every target finite and within ±[`MAX_POSITION`], and no (target, run, direction)
/// repeated (a repeated row would be counted twice by every evaluation). Returns the 0-based row
/// and the message of the first problem.
pub fn check_point_rows(target: &[f64], run: &[u32], direction: &[i8]) -> Result<(), (usize, String)> {
    if let Some(k) = target.iter().position(|x| !(x.is_finite() && x.abs() <= MAX_POSITION)) {
        return Err((k, format!("expected a target position within ±{MAX_POSITION} m, got {} m", fmt_num(target[k]))));
    }
    let mut seen: std::collections::HashMap<(u64, u32, i8), usize> = std::collections::HashMap::new();
    for (k, ((x, r), d)) in target.iter().zip(run).zip(direction).enumerate() {
        // +0.0 and −0.0 are one position.
        let key = ((x + 0.0).to_bits(), *r, *d);
        if let Some(first) = seen.insert(key, k) {
            return Err((
                k,
                format!(
                    "repeats row {} (target {} m, run {r}, direction {d:+}): each (target, run, direction) must appear once",
                    first + 1,
                    fmt_num(*x)
                ),
            ));
        }
    }
    Ok(())
}

/// Why a time column has no one sample interval (the caller adds the file and run).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SampleIntervalError {
    /// Fewer than two samples.
    #[error("expected at least two samples of `t` to have a sample interval, got {samples}")]
    TooFew {
        /// Samples in the column.
        samples: usize,
    },
    /// The last time is not after the first (or not finite).
    #[error("expected `t` increasing, got {} to {}", fmt_num(*.first), fmt_num(*.last))]
    NotIncreasing {
        /// First time, s.
        first: f64,
        /// Last time, s.
        last: f64,
    },
    /// A step deviates from the mean step by more than 1e-3 of it.
    #[error(
        "expected uniformly sampled `t` (median step {} s), got a step of {} s ending at data row {row}: this \
         estimator needs a constant sample rate",
        fmt_num(*.interval),
        fmt_num(*.step)
    )]
    NonUniform {
        /// The median step, s.
        interval: f64,
        /// The deviating step, s.
        step: f64,
        /// The data row (1-based, after the header) the step ends on.
        row: usize,
    },
}

/// The sample interval of a uniformly sampled time column, s: Δt = (t_last − t_0)/(n − 1), with every
/// step t_k+1 − t_k within 1e-3 of the median step h (CSV rounding, not a missing sample; then Δt is
/// within 1e-3 of h too). The median, not Δt, is the reference so that the error names the row where a
/// step deviates: one late sample shifts Δt and would make every other step deviate from it.
/// For estimators that take one rate (SSI, accelerometer straightness). Errors on fewer than two
/// samples or a non-uniform step, naming the row.
pub fn uniform_interval(t: &[f64]) -> Result<f64, SampleIntervalError> {
    let n = t.len();
    if n < 2 {
        return Err(SampleIntervalError::TooFew { samples: n });
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(SampleIntervalError::NotIncreasing { first: t[0], last: t[n - 1] });
    }
    let steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = steps.clone();
    sorted.sort_by(f64::total_cmp);
    let h = sorted[sorted.len() / 2];
    // A NaN step or a non-positive median deviates (`is_some_and` is false on NaN).
    let within = |s: f64| (s - h).abs().partial_cmp(&(1e-3 * h)).is_some_and(|o| o.is_le());
    if let Some(k) = steps.iter().position(|&s| !within(s)) {
        return Err(SampleIntervalError::NonUniform { interval: h, step: steps[k], row: k + 2 });
    }
    Ok(dt)
}

/// Checks that `t` increases strictly; the error names the line of the offending row.
fn check_increasing(csv: &CsvText, path: &Path, t: &[f64], col: &str) -> Result<(), VmtError> {
    if let Some(i) = t.windows(2).position(|w| w[1] <= w[0]) {
        return Err(VmtError::bad(
            path,
            format!("line {}, column {col}", csv.line(i + 1)),
            format!("`{col}` must increase strictly, got {} after {}", fmt_num(t[i + 1]), fmt_num(t[i])),
        ));
    }
    Ok(())
}

/// Reads one run's CSV; `sensors` gives the kinds (hence units) of sensor columns. Returns the
/// data and the whole seconds a time series' `t` is counted from ([`CsvText::times`]; 0 for a
/// point table), which the caller adds to the run's `start_time`.
fn read_run_data(path: &Path, sensors: &[Sensor]) -> Result<(RunData, f64), VmtError> {
    let csv = read_csv_text(path)?;
    let is_table = csv.index("target").is_some();
    let mut columns: Vec<(String, Vec<f64>)> = Vec::new();
    for (i, (name, _)) in csv.header.iter().enumerate() {
        if RESERVED.contains(&name.as_str()) {
            continue;
        }
        let dim = if let Some(s) = sensors.iter().find(|s| s.name == *name) {
            kind_dimension(s.kind)
        } else if is_command_column(name) {
            Dimension::Length
        } else {
            let known: Vec<&str> = sensors.iter().map(|s| s.name.as_str()).collect();
            return Err(VmtError::bad(
                path,
                format!("column {name}"),
                format!(
                    "unknown column `{name}`: expected a sensor of manifest.toml ({}), \
                     x_cmd/y_cmd/z_cmd, or {}",
                    if known.is_empty() { "none declared".to_string() } else { known.join(", ") },
                    if is_table { "target, run, direction, t" } else { "t" }
                ),
            ));
        };
        columns.push((name.clone(), csv.numbers(path, i, dim)?));
    }
    if !is_table {
        for r in ["run", "direction"] {
            if csv.index(r).is_some() {
                return Err(VmtError::bad(
                    path,
                    format!("column {r}"),
                    format!(
                        "column `{r}` belongs to a point table, which needs a `target` column \
                         (m): add it, or remove `{r}` for a time series"
                    ),
                ));
            }
        }
        let ti = csv.index("t").ok_or_else(|| {
            VmtError::bad(
                path,
                "line 1 (header)",
                "missing column `t`: a time series needs `t` (s, increasing); a point table needs \
                 `target`, `run`, `direction`",
            )
        })?;
        let (t, origin) = csv.times(path, ti)?;
        check_increasing(&csv, path, &t, "t")?;
        return Ok((RunData::TimeSeries { t, columns }, origin));
    }
    let need = |c: &str| {
        csv.index(c).ok_or_else(|| {
            VmtError::bad(
                path,
                "line 1 (header)",
                format!(
                    "missing column `{c}`: a point table needs `target` (m), `run` (1..n) and \
                     `direction` (+1/-1)"
                ),
            )
        })
    };
    let target = csv.numbers(path, need("target")?, Dimension::Length)?;
    let ri = need("run")?;
    let di = need("direction")?;
    let run_raw = csv.unitless(path, ri, "run numbers")?;
    let dir_raw = csv.unitless(path, di, "directions")?;
    let mut run: Vec<u32> = Vec::with_capacity(run_raw.len());
    let mut direction: Vec<i8> = Vec::with_capacity(dir_raw.len());
    for (k, (&r, &d)) in run_raw.iter().zip(&dir_raw).enumerate() {
        if r < 1.0 || r.fract() != 0.0 || r > f64::from(u32::MAX) {
            return Err(VmtError::bad(
                path,
                format!("line {}, column run", csv.line(k)),
                format!("expected a run number 1, 2, 3, ..., got {}", fmt_num(r)),
            ));
        }
        if d != 1.0 && d != -1.0 {
            return Err(VmtError::bad(
                path,
                format!("line {}, column direction", csv.line(k)),
                format!("expected +1 or -1, got {}", fmt_num(d)),
            ));
        }
        run.push(r as u32);
        direction.push(d as i8);
    }
    let t = match csv.index("t") {
        Some(ti) => Some(csv.numbers(path, ti, Dimension::Time)?),
        None => None,
    };
    check_point_rows(&target, &run, &direction)
        .map_err(|(k, m)| VmtError::bad(path, format!("line {}, column target", csv.line(k)), m))?;
    Ok((RunData::PointTable { target, run, direction, t, columns }, 0.0))
}

// ------------------------------------------------------------------------------------------
// Manifest.

fn vec3(r: &TomlReader<'_>, key: &str, what: &str) -> Result<Option<[f64; 3]>, VmtError> {
    match r.opt_f64_array(key, what)? {
        None => Ok(None),
        Some(v) if v.len() == 3 => Ok(Some([v[0], v[1], v[2]])),
        Some(v) => Err(r.bad(key, format!("expected 3 numbers ({what}), got {}", v.len()))),
    }
}

fn parse_sensor(r: &TomlReader<'_>) -> Result<Sensor, VmtError> {
    let name = r.req_str("name", "the sensor's CSV column name")?.to_string();
    let kind_s = r.req_str("kind", "a sensor kind")?;
    let kind = SensorKind::parse(kind_s).ok_or_else(|| {
        let known: Vec<&str> = SensorKind::ALL.iter().map(|k| k.as_str()).collect();
        r.bad("kind", format!("unknown sensor kind {kind_s:?}; expected one of {}", known.join(", ")))
    })?;
    let axis = r
        .opt_axis("axis")?
        .ok_or_else(|| r.bad("axis", "missing key: expected the axis observed, \"x\", \"y\" or \"z\""))?;
    let position = vec3(r, "position", "a measuring point in metres")?.unwrap_or([0.0, 0.0, 0.0]);
    let direction = vec3(r, "direction", "a sensitive direction")?.unwrap_or_else(|| axis.unit());
    let sigma = r.opt_f64("sigma", "a 1-sigma noise in SI units of the channel")?;
    let closes_loop = r.opt_bool("closes_loop")?.unwrap_or(false);
    if closes_loop && !matches!(kind, SensorKind::EncoderLinear | SensorKind::EncoderRotary) {
        return Err(r.bad("closes_loop", format!("only an encoder closes the position loop, not a `{kind_s}` sensor")));
    }
    let noise_density = r.opt_f64("noise_density", "a one-sided noise density in m/s²/√Hz")?;
    let highpass = r.opt_f64("highpass", "an AC-coupling corner frequency in Hz")?;
    r.deny_unknown()?;
    Ok(Sensor { name, kind, axis, position, direction, sigma, closes_loop, noise_density, highpass })
}

/// A run's manifest entry before its data is read.
fn parse_run_entry(r: &TomlReader<'_>) -> Result<(Run, String), VmtError> {
    let name = r.req_str("name", "the run's name")?.to_string();
    let file = r.req_str("file", "the run's CSV file name")?.to_string();
    let ps = r.req_str("procedure", "a procedure")?;
    let procedure = Procedure::parse(ps).ok_or_else(|| {
        let known: Vec<&str> = Procedure::ALL.iter().map(|p| p.as_str()).collect();
        r.bad("procedure", format!("unknown procedure {ps:?}; expected one of {}", known.join(", ")))
    })?;
    let axis = r
        .opt_axis("axis")?
        .ok_or_else(|| r.bad("axis", "missing key: expected the axis moved, \"x\", \"y\" or \"z\""))?;
    let start_time = r.opt_f64("start_time", "a time in seconds")?;
    let feed = r.opt_f64("feed", "a feed in m/s")?;
    let direction = match r.opt_i64("direction", "+1 or -1")? {
        None => None,
        Some(d) if d == 1 || d == -1 => Some(d as i8),
        Some(d) => return Err(r.bad("direction", format!("expected +1 or -1, got {d}"))),
    };
    r.deny_unknown()?;
    Ok((
        Run {
            name,
            file: file.clone(),
            procedure,
            axis,
            start_time,
            feed,
            direction,
            data: RunData::TimeSeries { t: Vec::new(), columns: Vec::new() },
        },
        file,
    ))
}

/// True if `file` is a plain relative path inside the set (no `..`, not absolute).
fn is_safe_relative(file: &str) -> bool {
    let p = Path::new(file);
    !file.is_empty() && p.components().all(|c| matches!(c, Component::Normal(_)))
}

/// Reads what `--data` names: a measurement set directory ([`read`]), or an ISO 230-2 test in the
/// ecmc key=value `.dat` format (a file; [`read_dat`], [`from_iso230_2_dat`]).
pub fn read_data(path: &Path) -> Result<MeasurementSet, VmtError> {
    if path.is_file() && path.extension().is_some_and(|e| e.eq_ignore_ascii_case("dat")) {
        return Ok(from_iso230_2_dat(&read_dat(path)?));
    }
    read(path)
}

/// Reads an ISO 230-2 test in the ecmc key=value `.dat` format, with the checks every command that
/// reads one applies: each target a finite position within ±[`MAX_POSITION`], distinct from the
/// others, and every reading within half the smallest target spacing of its target (a deviation that
/// large cannot be attributed to its target: the file is in another unit or a target is mistyped;
/// ISO 230-2 deviations are µm to mm on targets mm to m apart).
pub fn read_dat(path: &Path) -> Result<vmt_estimators::iso230_2::dat::DatFile, VmtError> {
    let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading the ISO 230-2 test", e))?;
    let dat = vmt_estimators::iso230_2::dat::parse_dat(&text).map_err(|e| VmtError::bad(path, "", e.to_string()))?;
    for (k, x) in dat.targets.iter().enumerate() {
        if !(x.is_finite() && x.abs() <= MAX_POSITION) {
            return Err(VmtError::bad(
                path,
                format!("target {}", k + 1),
                format!("expected a target position within ±{MAX_POSITION} m, got {} m", fmt_num(*x)),
            ));
        }
        if let Some(j) = dat.targets[..k].iter().position(|y| y == x) {
            return Err(VmtError::bad(
                path,
                format!("target {}", k + 1),
                format!(
                    "the same position {} m as target {}: each target must be a distinct position",
                    fmt_num(*x),
                    j + 1
                ),
            ));
        }
    }
    let mut sorted = dat.targets.clone();
    sorted.sort_by(f64::total_cmp);
    let spacing = sorted.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    for (table, name) in [(&dat.up, "REF_DATA_FWD"), (&dat.down, "REF_DATA_BWD")] {
        for (i, row) in table.iter().enumerate() {
            if let Some((j, d)) = row
                .iter()
                .enumerate()
                .find(|(_, d)| d.abs().partial_cmp(&(0.5 * spacing)) != Some(std::cmp::Ordering::Less))
            {
                return Err(VmtError::bad(
                    path,
                    format!("{name}[{},{}]", i + 1, j + 1),
                    format!(
                        "expected a reading within half the smallest target spacing ({} m) of its target {} m, \
                         got a deviation of {} m (another unit, or a mistyped target?)",
                        fmt_num(0.5 * spacing),
                        fmt_num(dat.targets[i]),
                        fmt_num(*d)
                    ),
                ));
            }
        }
    }
    Ok(dat)
}

/// An ISO 230-2 test (`.dat`) as a measurement set: one reference sensor `ref` (a linear laser along
/// the axis at its reference point, σ unknown) and one point-table run `iso` holding the deviations
/// in the order of the ISO cycle (per cycle: every target upwards, then downwards).
pub fn from_iso230_2_dat(dat: &vmt_estimators::iso230_2::dat::DatFile) -> MeasurementSet {
    let cycles = dat.up.iter().chain(&dat.down).map(Vec::len).min().unwrap_or(0);
    let mut order: Vec<usize> = (0..dat.targets.len()).collect();
    order.sort_by(|a, b| dat.targets[*a].total_cmp(&dat.targets[*b]));
    let (mut target, mut run, mut direction, mut y) = (vec![], vec![], vec![], vec![]);
    for j in 0..cycles {
        for (d, readings, targets) in
            [(1i8, &dat.up, order.clone()), (-1, &dat.down, order.iter().rev().copied().collect())]
        {
            for i in targets {
                target.push(dat.targets[i]);
                run.push(j as u32 + 1);
                direction.push(d);
                y.push(readings[i][j]);
            }
        }
    }
    MeasurementSet {
        description: Some("ISO 230-2 test (.dat)".into()),
        machine: None,
        seed: None,
        sensors: vec![Sensor {
            name: "ref".into(),
            kind: SensorKind::LaserLinear,
            axis: Axis::X,
            position: [0.0; 3],
            direction: [1.0, 0.0, 0.0],
            sigma: None,
            closes_loop: false,
            noise_density: None,
            highpass: None,
        }],
        runs: vec![Run {
            name: "iso".into(),
            file: "iso.csv".into(),
            procedure: Procedure::Positioning,
            axis: Axis::X,
            start_time: None,
            feed: None,
            direction: None,
            data: RunData::PointTable { target, run, direction, t: None, columns: vec![("ref".into(), y)] },
        }],
    }
}

/// Reads a measurement set from directory `dir`: `manifest.toml` (format `vmt-measurements/1`,
/// unknown keys rejected) and every run's CSV, converted to SI. Every problem is a
/// [`VmtError::BadInput`] naming the file and the key path or line and column.
pub fn read(dir: &Path) -> Result<MeasurementSet, VmtError> {
    let mpath = dir.join("manifest.toml");
    if !dir.is_dir() {
        return Err(VmtError::bad(
            dir,
            "",
            "expected a measurement set: a directory holding manifest.toml and CSV files",
        ));
    }
    let text = std::fs::read_to_string(&mpath).map_err(|e| VmtError::io(&mpath, "reading the manifest", e))?;
    let table = parse_toml(&mpath, &text)?;
    let r = TomlReader::new(&mpath, "", &table);
    let format = r.req_str("format", &format!("\"{FORMAT_ID}\""))?;
    if format != FORMAT_ID {
        return Err(r.bad("format", format!("expected \"{FORMAT_ID}\", got {format:?}")));
    }
    let description = r.opt_str("description", "a string")?.map(str::to_string);
    let machine = r.opt_str("machine", "a bundled machine name or URDF path")?.map(str::to_string);
    let seed = r.opt_u64("seed", "a non-negative integer seed")?;
    let sensor_tables = r.opt_tables("sensors")?.unwrap_or_default();
    // Size budget before any per-sensor work (the name checks compare every pair): each sensor is a
    // CSV column, so the column limit bounds them; runs are files.
    if sensor_tables.len() > MAX_COLUMNS {
        return Err(r.bad(
            "sensors",
            format!("{} sensors; the limit is {MAX_COLUMNS} (one CSV column each)", sensor_tables.len()),
        ));
    }
    let sensors: Vec<Sensor> = sensor_tables.iter().map(parse_sensor).collect::<Result<Vec<Sensor>, VmtError>>()?;
    let entries = r.opt_tables("runs")?.unwrap_or_default();
    if entries.len() > MAX_RUNS {
        return Err(r.bad("runs", format!("{} runs; the limit is {MAX_RUNS} (one CSV file each)", entries.len())));
    }
    r.deny_unknown()?;
    let mut runs: Vec<Run> = Vec::with_capacity(entries.len());
    let mut set_so_far = MeasurementSet { description, machine, seed, sensors, runs: Vec::new() };
    // Manifest-level checks (names, ranges) before touching the CSV files.
    let mut parsed: Vec<(Run, String)> = Vec::new();
    for e in &entries {
        parsed.push(parse_run_entry(e)?);
    }
    set_so_far.runs = parsed.iter().map(|(r, _)| r.clone()).collect();
    validate_manifest(&set_so_far, &mpath)?;
    for (mut run, file) in parsed {
        let (data, origin) = read_run_data(&dir.join(&file), &set_so_far.sensors)?;
        run.data = data;
        if origin != 0.0 {
            run.start_time = Some(run.start_time.unwrap_or(0.0) + origin);
        }
        runs.push(run);
    }
    set_so_far.runs = runs;
    validate(&set_so_far, &mpath)?;
    Ok(set_so_far)
}

/// A valid sensor / column name: non-empty, no whitespace, none of `,[]#"`.
fn valid_column_name(s: &str) -> bool {
    !s.is_empty() && !s.chars().any(|c| c.is_whitespace() || matches!(c, ',' | '[' | ']' | '#' | '"'))
}

/// Checks the manifest part of a set (sensors and run entries): unique valid names, safe file
/// names, finite geometry, a non-zero direction, σ ≥ 0, feed > 0. Errors name `file` (the
/// manifest) and the key path, e.g. `sensors[1].sigma`.
pub fn validate_manifest(set: &MeasurementSet, file: &Path) -> Result<(), VmtError> {
    let bad = |place: String, m: String| Err(VmtError::bad(file, place, m));
    for (i, s) in set.sensors.iter().enumerate() {
        if !valid_column_name(&s.name) {
            return bad(
                format!("sensors[{i}].name"),
                format!(
                    "expected a CSV column name (no spaces, commas, brackets, # or quotes), \
                     got {:?}",
                    s.name
                ),
            );
        }
        if RESERVED.contains(&s.name.as_str()) {
            return bad(
                format!("sensors[{i}].name"),
                format!("`{}` is reserved for the CSV's own columns (t, target, run, direction)", s.name),
            );
        }
        if set.sensors[..i].iter().any(|o| o.name == s.name) {
            return bad(format!("sensors[{i}].name"), format!("sensor `{}` is declared twice", s.name));
        }
        if s.position.iter().any(|v| !v.is_finite()) {
            return bad(format!("sensors[{i}].position"), "expected 3 finite numbers (m)".to_string());
        }
        let n2: f64 = s.direction.iter().map(|v| v * v).sum();
        if !n2.is_finite() || n2 == 0.0 {
            return bad(
                format!("sensors[{i}].direction"),
                format!("expected a non-zero finite direction, got {:?}", s.direction),
            );
        }
        if let Some(sg) = s.sigma {
            if !(sg.is_finite() && sg >= 0.0) {
                return bad(
                    format!("sensors[{i}].sigma"),
                    format!("expected a 1-sigma noise in SI units of the channel ≥ 0, got {}", fmt_num(sg)),
                );
            }
        }
        if let Some(rho) = s.noise_density {
            if !(rho.is_finite() && rho > 0.0) {
                return bad(
                    format!("sensors[{i}].noise_density"),
                    format!("expected a one-sided noise density > 0 (m/s²/√Hz), got {}", fmt_num(rho)),
                );
            }
        }
        if let Some(hp) = s.highpass {
            if !(hp.is_finite() && hp >= 0.0) {
                return bad(
                    format!("sensors[{i}].highpass"),
                    format!("expected an AC-coupling corner ≥ 0 (Hz), got {}", fmt_num(hp)),
                );
            }
        }
    }
    if set.runs.is_empty() {
        return bad("runs".to_string(), "expected at least one [[runs]] entry".to_string());
    }
    for (i, r) in set.runs.iter().enumerate() {
        if r.name.is_empty() {
            return bad(format!("runs[{i}].name"), "expected a non-empty name".into());
        }
        if set.runs[..i].iter().any(|o| o.name == r.name) {
            return bad(format!("runs[{i}].name"), format!("run `{}` is declared twice", r.name));
        }
        if !is_safe_relative(&r.file) || r.file == "manifest.toml" {
            return bad(
                format!("runs[{i}].file"),
                format!(
                    "expected a CSV file name relative to the set's directory (no `..`, not \
                     absolute), got {:?}",
                    r.file
                ),
            );
        }
        if set.runs[..i].iter().any(|o| o.file == r.file) {
            return bad(format!("runs[{i}].file"), format!("file {:?} is used by two runs", r.file));
        }
        if let Some(t0) = r.start_time {
            if !t0.is_finite() {
                return bad(format!("runs[{i}].start_time"), "expected a finite time in seconds".into());
            }
        }
        if let Some(f) = r.feed {
            if !(f.is_finite() && f > 0.0) {
                return bad(format!("runs[{i}].feed"), format!("expected a feed in m/s > 0, got {}", fmt_num(f)));
            }
        }
        if let Some(d) = r.direction {
            if d != 1 && d != -1 {
                return bad(format!("runs[{i}].direction"), format!("expected +1 or -1, got {d}"));
            }
        }
    }
    Ok(())
}

/// Checks a whole set (manifest part, then every run's data: equal column lengths, finite
/// values, strictly increasing `t`, run numbers ≥ 1, directions ±1, columns that are sensors or
/// x_cmd/y_cmd/z_cmd). Used by the writer so that nothing is written that the reader would reject.
pub fn validate(set: &MeasurementSet, file: &Path) -> Result<(), VmtError> {
    validate_manifest(set, file)?;
    for (i, r) in set.runs.iter().enumerate() {
        let place = |what: String| format!("runs[{i}] ({}): {what}", r.name);
        let bad = |what: String, m: String| Err(VmtError::bad(file, place(what), m));
        let n = r.data.len();
        if n == 0 {
            return bad("data".into(), "expected at least one row".into());
        }
        let check = |name: &str, v: &[f64]| -> Result<(), VmtError> {
            if v.len() != n {
                return Err(VmtError::bad(
                    file,
                    place(format!("column {name}")),
                    format!("expected {n} values like the other columns, got {}", v.len()),
                ));
            }
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(VmtError::bad(
                    file,
                    place(format!("column {name}, row {}", k + 1)),
                    format!("expected a finite number, got {}", v[k]),
                ));
            }
            Ok(())
        };
        let mut seen: BTreeSet<&str> = BTreeSet::new();
        for (name, v) in r.data.columns() {
            if set.sensor(name).is_none() && !is_command_column(name) {
                return bad(
                    format!("column {name}"),
                    format!("`{name}` is neither a declared sensor nor x_cmd/y_cmd/z_cmd"),
                );
            }
            if !seen.insert(name) {
                return bad(format!("column {name}"), "column appears twice".into());
            }
            check(name, v)?;
        }
        match &r.data {
            RunData::TimeSeries { t, .. } => {
                check("t", t)?;
                if let Some(k) = t.windows(2).position(|w| w[1] <= w[0]) {
                    return bad(
                        format!("column t, row {}", k + 2),
                        format!("`t` must increase strictly, got {} after {}", fmt_num(t[k + 1]), fmt_num(t[k])),
                    );
                }
            }
            RunData::PointTable { target, run, direction, t, .. } => {
                check("target", target)?;
                if let Some(t) = t {
                    check("t", t)?;
                }
                if run.len() != n || direction.len() != n {
                    return bad("columns run, direction".into(), format!("expected {n} values like `target`"));
                }
                if let Some(k) = run.iter().position(|&x| x < 1) {
                    return bad(
                        format!("column run, row {}", k + 1),
                        format!("expected a run number 1, 2, 3, ..., got {}", run[k]),
                    );
                }
                if let Some(k) = direction.iter().position(|&d| d != 1 && d != -1) {
                    return bad(
                        format!("column direction, row {}", k + 1),
                        format!("expected +1 or -1, got {}", direction[k]),
                    );
                }
                if let Err((k, m)) = check_point_rows(target, run, direction) {
                    return bad(format!("column target, row {}", k + 1), m);
                }
            }
        }
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------
// Writing.

/// The unit a writer uses for a column of dimension `dim` (`position_like`: t, target, commands,
/// encoders, which are written in mm rather than um under `Metrology`).
fn write_unit(dim: Dimension, position_like: bool, choice: UnitChoice) -> Unit {
    let sym = match (choice, dim) {
        (UnitChoice::Si, _) => return dim.si(),
        (UnitChoice::Metrology, Dimension::Length) if position_like => "mm",
        (UnitChoice::Metrology, Dimension::Length) => "um",
        (UnitChoice::Metrology, Dimension::Angle) => "urad",
        (UnitChoice::Metrology, Dimension::Velocity) => "mm/s",
        (UnitChoice::Metrology, Dimension::Temperature) => "degC",
        (UnitChoice::Metrology, Dimension::Ratio) => "percent",
        (UnitChoice::Metrology, d) => return d.si(),
    };
    crate::units::unit(sym).unwrap_or_else(|| dim.si())
}

/// A header cell `name[unit]`, or `name` for SI; under `--units human` every cell names its unit,
/// SI ones too (`t[s]`, `acc_z[m/s^2]`, `force[N]`), so that no column of such a file is unitless.
fn header_cell(name: &str, u: &Unit, choice: UnitChoice) -> String {
    if u.is_si() && (choice == UnitChoice::Si || u.dimension == Dimension::Ratio) {
        name.to_string()
    } else {
        format!("{name}[{}]", u.symbol)
    }
}

/// CSV text of columns of equal length: header cells and per-column (unit, values); integer
/// columns are passed as already formatted strings.
enum Col<'a> {
    Num(Unit, &'a [f64]),
    Int(Vec<String>),
}

/// The number with the fewest significant digits (1 to 17) whose conversion `back` to SI lands within
/// one ulp of `si` (|back(r) − si| ≤ ulp(si), a relative 2.2e-16); `x` itself (the full shortest
/// representation) when none shorter does. One ulp, not exact equality: a 0.001 µm-resolution reading
/// stored as −5.372e-6 m has no decimal in µm whose division by 10⁶ gives that very double (−5.372/10⁶
/// rounds to its neighbour), and exact equality wrote it −5.372000000000001 µm — noise a reader takes
/// for a digit (issue 13).
fn shortest_round_trip(x: f64, back: impl Fn(f64) -> f64, si: f64) -> f64 {
    let ulp = si.abs().next_up() - si.abs();
    (1..=17usize)
        .filter_map(|p| format!("{:.*e}", p - 1, x).parse::<f64>().ok())
        .find(|&r| (back(r) - si).abs() <= ulp)
        .unwrap_or(x)
}

/// `si` written in unit `u` as a CSV cell: SI values exactly ([`fmt_f64`]), converted ones with the
/// fewest digits that read back (through `u`) to within one ulp of `si` (335.95 mm, not
/// 335.95000000000005). Callers check that the converted value is finite.
pub fn fmt_in_unit(u: &Unit, si: f64) -> String {
    if u.is_si() {
        fmt_f64(si)
    } else {
        fmt_f64(shortest_round_trip(u.from_si(si), |r| u.to_si(r), si))
    }
}

/// A value that overflows when written in the unit chosen (the caller adds the file).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("column {column}, row {row}: {} (SI) overflows when written in {unit}; write in SI units", fmt_num(*.value))]
struct UnitOverflow {
    column: String,
    row: usize,
    value: f64,
    unit: &'static str,
}

fn csv_text(header: &[String], cols: &[Col<'_>], n: usize) -> Result<String, UnitOverflow> {
    let mut out = String::with_capacity(16 * (n + 1) * header.len().max(1));
    out.push_str(&header.join(","));
    out.push('\n');
    for i in 0..n {
        for (j, c) in cols.iter().enumerate() {
            if j > 0 {
                out.push(',');
            }
            match c {
                Col::Num(u, v) => {
                    let x = u.from_si(v[i]);
                    if !x.is_finite() {
                        return Err(UnitOverflow {
                            column: header[j].clone(),
                            row: i + 1,
                            value: v[i],
                            unit: u.symbol,
                        });
                    }
                    // A value converted out of SI (m → mm) carries the conversion's rounding noise
                    // (0.33595 m → 335.95000000000005 mm): written with the fewest significant digits
                    // that read back (through the same unit) to within one ulp of the SI value, so the
                    // file shows 335.95. SI values are written exactly.
                    out.push_str(&fmt_in_unit(u, v[i]));
                }
                Col::Int(v) => out.push_str(&v[i]),
            }
        }
        out.push('\n');
    }
    Ok(out)
}

/// The CSV text of one run.
fn run_csv(set: &MeasurementSet, run: &Run, units: UnitChoice) -> Result<String, UnitOverflow> {
    let mut header: Vec<String> = Vec::new();
    let mut cols: Vec<Col<'_>> = Vec::new();
    let time_u = write_unit(Dimension::Time, true, units);
    match &run.data {
        RunData::TimeSeries { t, .. } => {
            header.push(header_cell("t", &time_u, units));
            cols.push(Col::Num(time_u, t));
        }
        RunData::PointTable { target, run: rn, direction, t, .. } => {
            let lu = write_unit(Dimension::Length, true, units);
            header.push(header_cell("target", &lu, units));
            cols.push(Col::Num(lu, target));
            header.push("run".into());
            cols.push(Col::Int(rn.iter().map(|r| r.to_string()).collect()));
            header.push("direction".into());
            cols.push(Col::Int(direction.iter().map(|d| d.to_string()).collect()));
            if let Some(t) = t {
                header.push(header_cell("t", &time_u, units));
                cols.push(Col::Num(time_u, t));
            }
        }
    }
    for (name, v) in run.data.columns() {
        let (dim, pos) = match set.sensor(name) {
            Some(s) => (
                kind_dimension(s.kind),
                matches!(s.kind, SensorKind::Command | SensorKind::EncoderLinear | SensorKind::EncoderRotary),
            ),
            None => (Dimension::Length, true),
        };
        let u = write_unit(dim, pos, units);
        header.push(header_cell(name, &u, units));
        cols.push(Col::Num(u, v));
    }
    csv_text(&header, &cols, run.data.len())
}

/// A TOML array of floats.
fn toml_f64_array(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| fmt_toml_f64(*x)).collect();
    format!("[{}]", items.join(", "))
}

/// The manifest text of a set.
fn manifest_text(set: &MeasurementSet) -> Result<String, VmtError> {
    let mut s = String::new();
    s.push_str("# vmt measurement set (vmt-measurements/1, docs/formats.md §1); CSV values in SI unless a header says [unit]\n");
    s.push_str(&format!("format = {}\n", toml_str(FORMAT_ID)));
    if let Some(d) = &set.description {
        s.push_str(&format!("description = {}\n", toml_str(d)));
    }
    if let Some(m) = &set.machine {
        s.push_str(&format!("machine = {}\n", toml_str(m)));
    }
    if let Some(seed) = set.seed {
        let seed_i = i64::try_from(seed)
            .map_err(|_| VmtError::Internal(format!("seed {seed} does not fit a TOML integer (at most 2^63 - 1)")))?;
        s.push_str(&format!("seed = {seed_i}\n"));
    }
    for x in &set.sensors {
        s.push_str("\n[[sensors]]\n");
        s.push_str(&format!("name = {}\n", toml_str(&x.name)));
        s.push_str(&format!("kind = {}\n", toml_str(x.kind.as_str())));
        s.push_str(&format!("axis = {}\n", toml_str(&x.axis.to_string())));
        s.push_str(&format!("position = {}\n", toml_f64_array(&x.position)));
        s.push_str(&format!("direction = {}\n", toml_f64_array(&x.direction)));
        if let Some(sg) = x.sigma {
            s.push_str(&format!("sigma = {}\n", fmt_toml_f64(sg)));
        }
        if x.closes_loop {
            s.push_str("closes_loop = true\n");
        }
        if let Some(rho) = x.noise_density {
            s.push_str(&format!("noise_density = {}\n", fmt_toml_f64(rho)));
        }
        if let Some(hp) = x.highpass {
            s.push_str(&format!("highpass = {}\n", fmt_toml_f64(hp)));
        }
    }
    for r in &set.runs {
        s.push_str("\n[[runs]]\n");
        s.push_str(&format!("name = {}\n", toml_str(&r.name)));
        s.push_str(&format!("file = {}\n", toml_str(&r.file)));
        s.push_str(&format!("procedure = {}\n", toml_str(r.procedure.as_str())));
        s.push_str(&format!("axis = {}\n", toml_str(&r.axis.to_string())));
        if let Some(t0) = r.start_time {
            s.push_str(&format!("start_time = {}\n", fmt_toml_f64(t0)));
        }
        if let Some(f) = r.feed {
            s.push_str(&format!("feed = {}\n", fmt_toml_f64(f)));
        }
        if let Some(d) = r.direction {
            s.push_str(&format!("direction = {d}\n"));
        }
    }
    Ok(s)
}

/// Writes a measurement set into directory `dir` atomically (see [`write_with_extras`]).
pub fn write(set: &MeasurementSet, dir: &Path, units: UnitChoice) -> Result<(), VmtError> {
    write_with_extras(set, dir, units, &[])
}

/// Writes a measurement set into directory `dir`, plus `extras` (file name, bytes) such as
/// `truth.toml` and `truth_profiles.csv` (FORMAT.md §5), all in one output transaction
/// ([`super::output::replace_dir`]): written into a temporary sibling directory which is then swapped
/// into place, replacing a previous vmt output or an empty directory.
/// The set is validated first ([`validate`]): nothing is written that [`read`] would reject.
pub fn write_with_extras(
    set: &MeasurementSet,
    dir: &Path,
    units: UnitChoice,
    extras: &[(String, Vec<u8>)],
) -> Result<(), VmtError> {
    let files = set_files(set, dir, units, extras)?;
    super::output::replace_dir(dir, |tmp| put_files(tmp, &files))
}

/// The files of a measurement set (relative name, bytes), the manifest last, plus `extras`; `dir`
/// names the destination in messages. Validates the set first.
pub fn set_files(
    set: &MeasurementSet,
    dir: &Path,
    units: UnitChoice,
    extras: &[(String, Vec<u8>)],
) -> Result<Vec<(String, Vec<u8>)>, VmtError> {
    let mpath = dir.join("manifest.toml");
    validate(set, &mpath)?;
    for (name, _) in extras {
        if !is_safe_relative(name) || name == "manifest.toml" || set.runs.iter().any(|r| r.file == *name) {
            return Err(VmtError::Internal(format!("extra file {name:?} is not a fresh relative name inside the set")));
        }
    }
    let manifest = manifest_text(set)?;
    let mut files: Vec<(String, Vec<u8>)> = set
        .runs
        .iter()
        .map(|r| {
            run_csv(set, r, units)
                .map(|text| (r.file.clone(), text.into_bytes()))
                .map_err(|m| VmtError::bad(&dir.join(&r.file), "", m.to_string()))
        })
        .collect::<Result<Vec<_>, VmtError>>()?;
    files.extend(extras.iter().cloned());
    // The manifest last: a set is complete when its manifest exists.
    files.push(("manifest.toml".into(), manifest.into_bytes()));
    Ok(files)
}

/// Writes files (relative name, bytes) into directory `dir`, creating subdirectories.
pub fn put_files(dir: &Path, files: &[(String, Vec<u8>)]) -> Result<(), VmtError> {
    for (name, bytes) in files {
        let p = dir.join(name);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).map_err(|e| VmtError::io(parent, "creating the directory", e))?;
        }
        write_synced(&p, bytes)?;
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------
// Error-motion profiles (FORMAT.md §5).

/// One error-motion column of a profile CSV: `pitch` or `y.pitch`, with optional `pitch_sigma`.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileColumn {
    /// Axis prefix (`y.pitch` → Y); `None` for an unprefixed column (the file's one axis).
    pub axis: Option<Axis>,
    /// Which error motion (positioning, straightness_y, straightness_z, roll, pitch, yaw).
    pub effect: EffectName,
    /// Values at the positions, m or rad.
    pub values: Vec<f64>,
    /// Standard errors, same unit, if given.
    pub sigma: Option<Vec<f64>>,
}

impl ProfileColumn {
    /// The column name in a file: `pitch` or `y.pitch`.
    pub fn column_name(&self) -> String {
        match self.axis {
            Some(a) => format!("{a}.{}", self.effect),
            None => self.effect.to_string(),
        }
    }
}

/// A truth or estimate of error motions over positions (FORMAT.md §5): `truth_profiles.csv`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProfileTable {
    /// Axis positions, m, strictly increasing.
    pub position: Vec<f64>,
    /// The error-motion columns.
    pub columns: Vec<ProfileColumn>,
}

impl ProfileTable {
    /// The column of `effect` on `axis`: an exact axis match first, then an unprefixed column.
    pub fn get(&self, effect: EffectName, axis: Axis) -> Option<&ProfileColumn> {
        self.columns
            .iter()
            .find(|c| c.effect == effect && c.axis == Some(axis))
            .or_else(|| self.columns.iter().find(|c| c.effect == effect && c.axis.is_none()))
    }
}

/// Why a profile CSV column name is refused (the caller adds the file and column).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
enum ProfileColumnError {
    #[error("column `{}`: bad axis prefix; {}", .0, PROFILE_COLUMN_EXPECTED)]
    AxisPrefix(String),
    #[error("unknown column `{}`: {}", .0, PROFILE_COLUMN_EXPECTED)]
    Unknown(String),
}

const PROFILE_COLUMN_EXPECTED: &str = "expected an error-motion column: positioning, straightness_y, \
                                       straightness_z, roll, pitch or yaw, optionally prefixed by the axis \
                                       (`y.pitch`) and suffixed `_sigma`";

/// Splits a profile column name into (axis, effect, is_sigma).
fn parse_profile_column(name: &str) -> Result<(Option<Axis>, EffectName, bool), ProfileColumnError> {
    let (base, sigma) = match name.strip_suffix("_sigma") {
        Some(b) => (b, true),
        None => (name, false),
    };
    let (axis, ename) = match base.split_once('.') {
        Some(("x", e)) => (Some(Axis::X), e),
        Some(("y", e)) => (Some(Axis::Y), e),
        Some(("z", e)) => (Some(Axis::Z), e),
        Some(_) => return Err(ProfileColumnError::AxisPrefix(name.to_string())),
        None => (None, base),
    };
    match ename.parse::<EffectName>() {
        Ok(e) if e.is_error_motion() => Ok((axis, e, sigma)),
        _ => Err(ProfileColumnError::Unknown(name.to_string())),
    }
}

/// Reads an error-motion profile CSV (FORMAT.md §5): a `position` column (length unit allowed),
/// one column per error motion (`pitch`, `y.pitch`; length or angle units per effect) and
/// optional `NAME_sigma` columns. Positions must increase strictly; values must be finite.
pub fn read_profiles(path: &Path) -> Result<ProfileTable, VmtError> {
    let csv = read_csv_text(path)?;
    let pi = csv.index("position").ok_or_else(|| {
        VmtError::bad(path, "line 1 (header)", "missing column `position` (axis position, m or a length unit)")
    })?;
    let position = csv.numbers(path, pi, Dimension::Length)?;
    check_increasing(&csv, path, &position, "position")?;
    let mut columns: Vec<ProfileColumn> = Vec::new();
    let mut sigmas: Vec<(usize, Option<Axis>, EffectName)> = Vec::new();
    for (i, (name, _)) in csv.header.iter().enumerate() {
        if i == pi {
            continue;
        }
        let (axis, effect, is_sigma) =
            parse_profile_column(name).map_err(|m| VmtError::bad(path, format!("column {name}"), m.to_string()))?;
        if is_sigma {
            sigmas.push((i, axis, effect));
            continue;
        }
        let dim = if effect.is_translational() { Dimension::Length } else { Dimension::Angle };
        columns.push(ProfileColumn { axis, effect, values: csv.numbers(path, i, dim)?, sigma: None });
    }
    for (i, axis, effect) in sigmas {
        let name = &csv.header[i].0;
        let dim = if effect.is_translational() { Dimension::Length } else { Dimension::Angle };
        let v = csv.numbers(path, i, dim)?;
        if let Some(k) = v.iter().position(|&s| s < 0.0) {
            return Err(VmtError::bad(
                path,
                format!("line {}, column {name}", csv.line(k)),
                format!("expected a standard error ≥ 0, got {}", fmt_num(v[k])),
            ));
        }
        let col = columns.iter_mut().find(|c| c.axis == axis && c.effect == effect).ok_or_else(|| {
            VmtError::bad(
                path,
                format!("column {name}"),
                format!("`{name}` has no value column `{}`", name.trim_end_matches("_sigma")),
            )
        })?;
        col.sigma = Some(v);
    }
    Ok(ProfileTable { position, columns })
}

/// Checks a profile table before writing: positions strictly increasing and finite, equal
/// lengths, finite values, σ ≥ 0, no column twice.
pub fn validate_profiles(table: &ProfileTable, file: &Path) -> Result<(), VmtError> {
    let n = table.position.len();
    let bad = |place: String, m: String| Err(VmtError::bad(file, place, m));
    if n == 0 {
        return bad("position".into(), "expected at least one position".into());
    }
    if table.position.iter().any(|x| !x.is_finite()) {
        return bad("position".into(), "expected finite positions".into());
    }
    if let Some(k) = table.position.windows(2).position(|w| w[1] <= w[0]) {
        return bad(
            format!("position, row {}", k + 2),
            format!(
                "positions must increase strictly, got {} after {}",
                fmt_num(table.position[k + 1]),
                fmt_num(table.position[k])
            ),
        );
    }
    for (i, c) in table.columns.iter().enumerate() {
        let name = c.column_name();
        if !c.effect.is_error_motion() {
            return bad(format!("column {name}"), "only the six error motions go in a profile CSV".into());
        }
        if table.columns[..i].iter().any(|o| o.axis == c.axis && o.effect == c.effect) {
            return bad(format!("column {name}"), "column appears twice".into());
        }
        let sig = c.sigma.as_deref().unwrap_or(&[]);
        if c.values.len() != n || (c.sigma.is_some() && sig.len() != n) {
            return bad(format!("column {name}"), format!("expected {n} values like `position`"));
        }
        if c.values.iter().chain(sig).any(|x| !x.is_finite()) || sig.iter().any(|&s| s < 0.0) {
            return bad(format!("column {name}"), "expected finite values and standard errors ≥ 0".into());
        }
    }
    Ok(())
}

/// Writes a profile CSV (FORMAT.md §5) atomically: `position`, then each column and its
/// `_sigma` column if any. With `Metrology` units: position in mm, lengths in um, angles in urad.
pub fn write_profiles(table: &ProfileTable, path: &Path, units: UnitChoice) -> Result<(), VmtError> {
    let text = profiles_csv(table, path, units)?;
    write_file_atomic(path, text.as_bytes())
}

/// The §5 profile CSV text of a table (`path` is named in messages only).
pub fn profiles_csv(table: &ProfileTable, path: &Path, units: UnitChoice) -> Result<String, VmtError> {
    validate_profiles(table, path)?;
    let pu = write_unit(Dimension::Length, true, units);
    let mut header: Vec<String> = vec![header_cell("position", &pu, units)];
    let mut cols: Vec<Col<'_>> = vec![Col::Num(pu, &table.position)];
    for c in &table.columns {
        let dim = if c.effect.is_translational() { Dimension::Length } else { Dimension::Angle };
        let u = write_unit(dim, false, units);
        let name = c.column_name();
        header.push(header_cell(&name, &u, units));
        cols.push(Col::Num(u, &c.values));
        if let Some(s) = &c.sigma {
            header.push(header_cell(&format!("{name}_sigma"), &u, units));
            cols.push(Col::Num(u, s));
        }
    }
    csv_text(&header, &cols, table.position.len()).map_err(|m| VmtError::bad(path, "", m.to_string()))
}

/// Reads a two-column table CSV (`position`, then `value` or `value_name`) as used by a model's
/// `table = "file.csv"`: returns (positions m, values in SI of dimension `value_dim`), positions
/// strictly increasing.
pub fn read_value_table(path: &Path, value_name: &str, value_dim: Dimension) -> Result<(Vec<f64>, Vec<f64>), VmtError> {
    let csv = read_csv_text(path)?;
    if csv.header.len() != 2 {
        return Err(VmtError::bad(
            path,
            "line 1 (header)",
            format!("expected two columns `position,value` (or `position,{value_name}`), got {}", csv.header.len()),
        ));
    }
    if csv.header[0].0 != "position" {
        return Err(VmtError::bad(
            path,
            "line 1 (header)",
            format!("expected the first column `position`, got `{}`", csv.header[0].0),
        ));
    }
    let vn = &csv.header[1].0;
    if vn != "value" && vn != value_name {
        return Err(VmtError::bad(
            path,
            "line 1 (header)",
            format!("expected the second column `value` (or `{value_name}`), got `{vn}`"),
        ));
    }
    let x = csv.numbers(path, 0, Dimension::Length)?;
    check_increasing(&csv, path, &x, "position")?;
    let y = csv.numbers(path, 1, value_dim)?;
    if x.len() < 2 {
        return Err(VmtError::bad(path, "", "expected at least two rows (position, value)"));
    }
    Ok((x, y))
}

/// The CSV text of a two-column table (`position,value`, SI, round-trip digits).
pub fn value_table_text(x: &[f64], y: &[f64]) -> String {
    let si = Dimension::Length.si();
    csv_text(&["position".to_string(), "value".to_string()], &[Col::Num(si, x), Col::Num(si, y)], x.len().min(y.len()))
        // SI units: no conversion, so no overflow; callers validate finiteness first.
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fmt_f64_round_trips_exactly_over_many_magnitudes() {
        // Deterministic pseudo-random bit patterns (xorshift) over the whole finite range.
        let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..20000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let x = f64::from_bits(s);
            if !x.is_finite() {
                continue;
            }
            let back: f64 = fmt_f64(x).parse().unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x:e} → {}", fmt_f64(x));
            let t: toml::Value =
                toml::from_str::<toml::Table>(&format!("v = {}", fmt_toml_f64(x))).unwrap()["v"].clone();
            assert_eq!(t.as_float().unwrap().to_bits(), x.to_bits());
        }
        assert_eq!(fmt_f64(-0.0), "-0");
        assert_eq!(fmt_toml_f64(2.0), "2.0");
        assert_eq!(fmt_f64(4e-9), "4e-9");
        assert_eq!(fmt_f64(0.25), "0.25");
        assert_eq!(fmt_f64(2.8e-5), "2.8e-5");
    }

    #[test]
    fn json_writes_and_reads_an_axis_as_its_letter() {
        let set = from_iso230_2_dat(&vmt_estimators::iso230_2::dat::DatFile {
            targets: vec![0.0, 0.1],
            up: vec![vec![1e-6], vec![2e-6]],
            down: vec![vec![1e-6], vec![2e-6]],
            unit: "mm".into(),
            metadata: Default::default(),
        });
        let json = serde_json::to_string(&set.sensors[0]).unwrap();
        assert!(json.contains("\"axis\":\"x\""), "{json}");
        assert_eq!(serde_json::from_str::<Sensor>(&json).unwrap(), set.sensors[0]);
        let bad = json.replace("\"axis\":\"x\"", "\"axis\":\"w\"");
        let e = serde_json::from_str::<Sensor>(&bad).unwrap_err().to_string();
        assert!(e.contains("expected an axis \"x\", \"y\" or \"z\", got 'w'"), "{e}");
    }

    /// Epoch-second stamps keep every written digit: the cells less the first's whole seconds in
    /// their text, the origin added to the run's start; small stamps are read as they were.
    #[test]
    fn epoch_second_stamps_are_counted_from_their_first_whole_second() {
        assert_eq!(relative_cell("1733400000.005750", 1_733_400_000.0), 0.00575);
        assert_eq!(relative_cell("1733400001.000001", 1_733_400_000.0), 1.000001);
        assert_eq!(relative_cell("-1733400000.25", -1_733_400_000.0), -0.25);
        assert_eq!(relative_cell("+1733400002", 1_733_400_000.0), 2.0);
        // Exponent form: the value as parsed, less the origin (exact: the two are close).
        assert_eq!(relative_cell("1.7334000005e9", 1_733_400_000.0), 0.5);
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        std::fs::write(
            dir.join("manifest.toml"),
            "format = \"vmt-measurements/1\"\n[[sensors]]\nname = \"scale\"\nkind = \"encoder_linear\"\naxis = \"x\"\n\
             [[runs]]\nname = \"a\"\nfile = \"a.csv\"\nprocedure = \"constant_velocity\"\naxis = \"x\"\nstart_time = 2.5\n\
             [[runs]]\nname = \"b\"\nfile = \"b.csv\"\nprocedure = \"constant_velocity\"\naxis = \"x\"\n",
        )
        .unwrap();
        let rows = |t: &[&str]| -> String {
            let body: Vec<String> = t.iter().enumerate().map(|(i, t)| format!("{t},{i},{i}")).collect();
            format!("t,x_cmd[mm],scale[mm]\n{}\n", body.join("\n"))
        };
        std::fs::write(dir.join("a.csv"), rows(&["1733400000.000000", "1733400000.000001", "1733400000.001251"]))
            .unwrap();
        std::fs::write(dir.join("b.csv"), rows(&["0.0", "0.001", "0.002"])).unwrap();
        let set = read(dir).unwrap();
        let RunData::TimeSeries { t, .. } = &set.runs[0].data else { panic!("a time series") };
        assert_eq!(t, &vec![0.0, 1e-6, 0.001251]);
        assert_eq!(set.runs[0].start_time, Some(1_733_400_002.5));
        let RunData::TimeSeries { t, .. } = &set.runs[1].data else { panic!("a time series") };
        assert_eq!(t, &vec![0.0, 0.001, 0.002]);
        assert_eq!(set.runs[1].start_time, None);
        // One run near 0 s: the set's times are counted from 0.
        assert_eq!(set.time_origin(), 0.0);
        let mut late = set.clone();
        late.runs[1].start_time = Some(1_733_400_010.75);
        assert_eq!(late.time_origin(), 1_733_400_002.0);
        assert_eq!(late.run_start(&late.runs[0]), 0.5);
        assert_eq!(late.run_start(&late.runs[1]), 8.75);
    }

    #[test]
    fn profile_column_names_parse_with_axis_and_sigma() {
        assert_eq!(parse_profile_column("y.pitch_sigma").unwrap(), (Some(Axis::Y), EffectName::Pitch, true));
        assert_eq!(parse_profile_column("straightness_y").unwrap(), (None, EffectName::StraightnessY, false));
        assert!(parse_profile_column("backlash").is_err());
        assert!(parse_profile_column("q.pitch").is_err());
    }
}
