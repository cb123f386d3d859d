//! Measurement procedures (DESIGN.md §6): what a metrologist runs on the machine. Each procedure is
//! planned into runs (commanded motion and record times, `plan_procedure`), the runs are placed one
//! after another on the session clock (`session_schedule`: time-dependent effects carry over between
//! runs) and simulated once into noise-free truth traces (`simulate_run`); sensors then read them with
//! seeded noise (`read_run`), as often as a tolerance study needs.

use crate::axis_sim::AxisTruth;
use crate::axis_sim::{simulate_in_session, Sample};
use crate::machine::AxisModel;
use crate::motion::MotionPlan;
use crate::rng::source_rng;
use crate::sensors::{apply_errors, true_readings, SensorError, SensorKind, SensorSpec};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Procedure names of FORMAT.md §1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProcedureKind {
    /// ISO 230-2 positioning: stops at targets, readings averaged at each stop (a point table).
    Positioning,
    /// Constant-velocity passes at one or more speeds (time series).
    ConstantVelocity,
    /// Low-speed crawl for stick-slip (time series).
    Crawl,
    /// Passes over decades of speed in both directions for the friction curve F(v) (time series).
    FrictionSweep,
    /// Any other run: motion and recording as the user gives them (time series).
    Free,
}

impl ProcedureKind {
    /// Every kind, in FORMAT.md §1's order.
    pub const ALL: [ProcedureKind; 5] = [
        ProcedureKind::Positioning,
        ProcedureKind::ConstantVelocity,
        ProcedureKind::Crawl,
        ProcedureKind::FrictionSweep,
        ProcedureKind::Free,
    ];

    /// Parses a manifest `procedure` string.
    pub fn parse(s: &str) -> Option<ProcedureKind> {
        ProcedureKind::ALL.iter().copied().find(|p| p.as_str() == s)
    }

    /// The manifest `procedure` string (FORMAT.md §1), e.g. `constant_velocity`.
    pub fn as_str(&self) -> &'static str {
        match self {
            ProcedureKind::Positioning => "positioning",
            ProcedureKind::ConstantVelocity => "constant_velocity",
            ProcedureKind::Crawl => "crawl",
            ProcedureKind::FrictionSweep => "friction_sweep",
            ProcedureKind::Free => "free",
        }
    }
}

/// Size budget of a scenario (DESIGN.md §2): limits on what input can make vmt allocate or compute,
/// checked before planning. Targets of one positioning or nine-line procedure.
pub const MAX_TARGETS: usize = 10_000;
/// Runs (bidirectional cycles) of one positioning procedure.
pub const MAX_RUNS: usize = 1_000;
/// Targets × runs of one positioning procedure (each visit is two motion segments).
pub const MAX_VISITS: usize = 100_000;
/// Speeds or feeds of one procedure.
pub const MAX_SPEEDS: usize = 1_000;
/// Recorded samples of one procedure (each sample holds the full rigid-body truth, ~200 bytes).
pub const MAX_SAMPLES: usize = 20_000_000;
/// Physics steps of one procedure (at ~2–5 µs a step: minutes to tens of minutes).
pub const MAX_STEPS: f64 = 5e8;
/// Longest dwell, settle, window or pause, s (about 11.6 days).
pub const MAX_SECONDS: f64 = 1e6;

// Defaults of the procedures' optional keys.
defaults! {
    d_dwell: f64 = 1.0;
    d_average: f64 = 0.2;
    d_rate: f64 = 500.0;
    d_runs: u32 = 5;
    d_targets: usize = 11;
    d_high_rate: f64 = 1200.0;
    d_one: i8 = 1;
    d_overrun: f64 = 0.005;
    d_duration: f64 = 1.0;
    d_crawl_rate: f64 = 2000.0;
    d_crawl_settle: f64 = 2.0;
    d_settle: f64 = 0.2;
    d_sweep_settle: f64 = 1.0;
    d_sweep_duration: f64 = 0.5;
    d_sweep_rate: f64 = 1000.0;
    d_per_decade: u32 = 2;
    d_sweep_vmin: f64 = 1e-5;
    d_sweep_vmax: f64 = 0.1;
}

/// An ISO 230-2 bidirectional positioning cycle ([`ProcedureSpec::Positioning`]): `targets` (or
/// `n_targets` irregularly spaced between start and end), `runs` linear cycles up and down with an
/// `overrun` before each reversal, dwell `dwell` s at each target, readings averaged over the last
/// `average` s sampled at `rate` Hz.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositioningSpec {
    /// Procedure name; its one run (a point table, `run` column 1..=runs) is named after it.
    pub name: String,
    /// Target positions, m; `None`: `n_targets` irregularly spaced between `start` and `end`.
    #[serde(default)]
    pub targets: Option<Vec<f64>>,
    /// Number of targets when `targets` is not given.
    #[serde(default = "d_targets")]
    pub n_targets: usize,
    /// First target (when `targets` is not given), m.
    pub start: f64,
    /// Last target (when `targets` is not given), m.
    pub end: f64,
    /// Bidirectional cycles (ISO 230-2: at least 5).
    #[serde(default = "d_runs")]
    pub runs: u32,
    /// Feed between targets, m/s.
    pub feed: f64,
    /// Stop at each target, s.
    #[serde(default = "d_dwell")]
    pub dwell: f64,
    /// Averaging window at the end of each stop, s (≤ `dwell`).
    #[serde(default = "d_average")]
    pub average: f64,
    /// Sample rate during the averaging window, Hz.
    #[serde(default = "d_rate")]
    pub rate: f64,
    /// Overrun beyond the end targets before each reversal, m (ISO 230-2's approach from one side).
    #[serde(default = "d_overrun")]
    pub overrun: f64,
    /// Acceleration of the moves, m/s² (default: the axis's max_accel).
    #[serde(default)]
    pub accel: Option<f64>,
    /// Names of the scenario's sensors read at each stop.
    pub sensors: Vec<String>,
}

/// A procedure as a scenario declares it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ProcedureSpec {
    /// Constant-velocity passes at several speeds with equal sample counts (seed 000): the highest speed is
    /// sampled at `high_rate` (default 1200 Hz), each other speed v at high_rate·v/v_max, over the range
    /// [start, end] (m) reached at full speed after `settle` seconds.
    ConstantVelocity {
        /// Procedure name; its runs are named `{name}_low`/`_mid`/`_high` for three speeds, else
        /// `{name}_{i}`, i = 1.. in increasing speed.
        name: String,
        /// Feeds of the passes, m/s, one run each.
        speeds: Vec<f64>,
        /// Start of the measured range, m (axis position).
        start: f64,
        /// End of the measured range, m (axis position).
        end: f64,
        /// Sample rate of the fastest pass, Hz; slower passes are sampled proportionally slower.
        #[serde(default = "d_high_rate")]
        high_rate: f64,
        /// Direction of the passes: +1 from `start` to `end`, −1 back.
        #[serde(default = "d_one")]
        direction: i8,
        /// Cruise time before the measured range, s (the axis reaches steady state at full speed).
        #[serde(default = "d_settle")]
        settle: f64,
        /// Names of the scenario's sensors that record the runs.
        sensors: Vec<String>,
    },
    /// ISO 230-2 bidirectional positioning cycle ([`PositioningSpec`]).
    Positioning(PositioningSpec),
    /// Low-speed crawl (seed 002): constant feeds from `start`, the sensors sampled at `rate` Hz
    /// (default 2 kHz) for `duration` s (default 1 s) once `settle` s (default 2 s) have passed.
    Crawl {
        /// Procedure name; its runs are named `{name}_{i}`, one per feed.
        name: String,
        /// Feeds, m/s (5 mm/min = 8.33e-5 m/s).
        feeds: Vec<f64>,
        /// Start position of every crawl, m.
        start: f64,
        /// Recorded window after `settle`, s.
        #[serde(default = "d_duration")]
        duration: f64,
        /// Sample rate, Hz.
        #[serde(default = "d_crawl_rate")]
        rate: f64,
        /// Time at the feed before recording starts, s.
        #[serde(default = "d_crawl_settle")]
        settle: f64,
        /// Direction of the crawl: +1 up, −1 down.
        #[serde(default = "d_one")]
        direction: i8,
        /// Names of the scenario's sensors that record the runs.
        sensors: Vec<String>,
    },
    /// Seed 003's laser 9-line / three-point measurement of one axis: targets every `step` m from start to
    /// end, one bidirectional run, every laser line read at every target.
    NineLine {
        /// Procedure name; its run is named after it.
        name: String,
        /// First target, m.
        start: f64,
        /// Last target, m.
        end: f64,
        /// Spacing of the targets, m (> 0).
        step: f64,
        /// Feed between targets, m/s.
        feed: f64,
        /// Stop at each target, s.
        #[serde(default = "d_dwell")]
        dwell: f64,
        /// Averaging window at the end of each stop, s (≤ `dwell`).
        #[serde(default = "d_average")]
        average: f64,
        /// Sample rate during the averaging window, Hz.
        #[serde(default = "d_rate")]
        rate: f64,
        /// Overrun beyond the end targets before the reversal, m.
        #[serde(default = "d_overrun")]
        overrun: f64,
        /// Names of the laser sensors read at each target (the 9 lines).
        sensors: Vec<String>,
    },
    /// Friction sweep (DESIGN.md §6, issue 3): constant-velocity passes over decades of speed, each speed in
    /// both directions, for the steady-state friction curve F(v) from the motor force. One time-series run
    /// per speed and direction (FORMAT.md §1: `procedure = "friction_sweep"`, `feed` = the speed,
    /// `direction` = ±1), named `{name}_{i}_pos` / `{name}_{i}_neg` with i = 1.. in increasing speed.
    ///
    /// The + pass starts at `start` and moves up, the − pass starts at `end` and moves down; after 0.5 s at
    /// rest each accelerates at the axis's max_accel a, cruises `settle` s (default 1 s) to reach steady
    /// state (at creep speeds the servo first builds up the break-away force Fs, then catches up its lag:
    /// ~0.5 s on slide_column), then is sampled at `rate` Hz (default 1 kHz) for a window of
    /// min(`duration`, T_c − settle) s, T_c = (end − start − v²/a)/v the cruise time the travel allows
    /// (default duration 0.5 s; fast passes get shorter windows). The steady-state friction is the window
    /// mean of the motor force minus the URDF axis damping·v; where the axis is in a stick-slip limit cycle
    /// the mean is only steady if the window spans many cycles.
    ///
    /// Speeds: `speeds` (m/s) if given, else `per_decade` log-spaced speeds per decade from `v_min` to
    /// `v_max` inclusive (defaults 2 per decade, 1e-5 to 0.1 m/s: four decades).
    FrictionSweep {
        /// Procedure name; its runs are named `{name}_{i}_pos` / `{name}_{i}_neg`.
        name: String,
        /// Speeds, m/s; `None`: log-spaced from `v_min` to `v_max`.
        #[serde(default)]
        speeds: Option<Vec<f64>>,
        /// Lowest speed of the log-spaced sweep, m/s.
        #[serde(default = "d_sweep_vmin")]
        v_min: f64,
        /// Highest speed of the log-spaced sweep, m/s.
        #[serde(default = "d_sweep_vmax")]
        v_max: f64,
        /// Speeds per decade of the log-spaced sweep.
        #[serde(default = "d_per_decade")]
        per_decade: u32,
        /// Lower end of the travel used by the passes, m.
        start: f64,
        /// Upper end of the travel used by the passes, m.
        end: f64,
        /// Cruise time before the sample window, s.
        #[serde(default = "d_sweep_settle")]
        settle: f64,
        /// Longest sample window, s.
        #[serde(default = "d_sweep_duration")]
        duration: f64,
        /// Sample rate, Hz.
        #[serde(default = "d_sweep_rate")]
        rate: f64,
        /// Names of the scenario's sensors that record the runs (at least the motor force).
        sensors: Vec<String>,
    },
    /// A break in the session: the machine stands still for `duration` s (warm-up, a night) before the
    /// next procedure; nothing is recorded, but time-dependent effects (thermal expansion, thermal
    /// drift) go on evolving on the session clock — repeating a test after a pause is what separates
    /// a thermal expansion from a scale error.
    Pause {
        /// Optional name of the pause (not a run).
        #[serde(default)]
        name: String,
        /// Length of the pause, s.
        duration: f64,
    },
}

/// Why a friction sweep cannot be planned: its speeds, or a sampled window at one of them on the axis.
/// Speeds in m/s, lengths in m, times in s, rates in Hz, accelerations in m/s².
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrictionSweepError {
    /// v_min, v_max not finite with 0 < v_min < v_max.
    #[error("friction sweep: expected 0 < v_min < v_max (finite, m/s), got v_min {v_min}, v_max {v_max}")]
    SpeedRange {
        /// Lowest speed, m/s.
        v_min: f64,
        /// Highest speed, m/s.
        v_max: f64,
    },
    /// `per_decade` outside 1..=[`MAX_SPEEDS`].
    #[error("friction sweep: per_decade must be in 1..={MAX_SPEEDS}, got {0}")]
    PerDecade(u32),
    /// More than [`MAX_SPEEDS`] speeds.
    #[error(
        "friction sweep: {count} speeds from v_min {v_min} to v_max {v_max} at {per_decade} per decade; the limit is {MAX_SPEEDS}"
    )]
    TooManySpeeds {
        /// Number of speeds the range makes.
        count: f64,
        /// Lowest speed, m/s.
        v_min: f64,
        /// Highest speed, m/s.
        v_max: f64,
        /// Speeds per decade.
        per_decade: u32,
    },
    /// An empty list of speeds.
    #[error("friction sweep: expected at least one speed")]
    NoSpeed,
    /// A speed ≤ 0 or not finite, m/s.
    #[error("friction sweep: speeds must be finite and > 0 m/s, got {0}")]
    BadSpeed(f64),
    /// A speed given twice, m/s.
    #[error("friction sweep: speeds must be distinct, got {0} twice")]
    RepeatedSpeed(f64),
    /// A key of the window that is not finite.
    #[error("friction sweep: {key} must be finite, got {value}")]
    NotFinite {
        /// The key (`start`, `end`, `settle`, `duration`, `rate`).
        key: &'static str,
        /// Its value, in the key's unit.
        value: f64,
    },
    /// The window's keys out of range.
    #[error(
        "friction sweep: expected end > start, accel > 0, settle ≥ 0, duration > 0, rate > 0, speed > 0; \
         got start {start}, end {end}, accel {accel}, settle {settle}, duration {duration}, rate {rate}, speed {speed}"
    )]
    Window {
        /// Start of the travel, m.
        start: f64,
        /// End of the travel, m.
        end: f64,
        /// Acceleration of the ramps, m/s².
        accel: f64,
        /// Settling time before the window, s.
        settle: f64,
        /// Window length asked for, s.
        duration: f64,
        /// Sample rate, Hz.
        rate: f64,
        /// Speed of the pass, m/s.
        speed: f64,
    },
    /// Fewer than 10 samples fit into the steady cruise at one speed.
    #[error(
        "friction sweep: at {speed} m/s the travel [{start}, {end}] m leaves {cruise_left:.4} s of steady cruise after \
         {settle} s of settling (ramps at {accel} m/s²); at least 10 samples at {rate} Hz are needed"
    )]
    ShortCruise {
        /// Speed of the pass, m/s.
        speed: f64,
        /// Start of the travel, m.
        start: f64,
        /// End of the travel, m.
        end: f64,
        /// Steady cruise left after settling, s.
        cruise_left: f64,
        /// Settling time, s.
        settle: f64,
        /// Acceleration of the ramps, m/s².
        accel: f64,
        /// Sample rate, Hz.
        rate: f64,
    },
    /// A speed above the axis's max feed.
    #[error("friction sweep: speed {speed} m/s exceeds the axis's max feed {max_feed} m/s")]
    AboveMaxFeed {
        /// The speed, m/s.
        speed: f64,
        /// The axis's max feed, m/s.
        max_feed: f64,
    },
}

/// Speeds of a friction sweep, m/s, increasing: the given `speeds` (sorted), else v_k = v_min·10^(k/n) for
/// k = 0..=K with n = `per_decade`, K = round(n·log10(v_max/v_min)) (so v_max is the last one up to the
/// rounding of the decade count). Errors on non-positive or non-finite speeds, v_max ≤ v_min, n = 0,
/// or duplicate speeds.
pub fn friction_sweep_speeds(
    speeds: Option<&[f64]>,
    v_min: f64,
    v_max: f64,
    per_decade: u32,
) -> Result<Vec<f64>, FrictionSweepError> {
    let mut v: Vec<f64> = match speeds {
        Some(s) => s.to_vec(),
        None => {
            if !(v_min.is_finite() && v_min > 0.0 && v_max.is_finite() && v_max > v_min) {
                return Err(FrictionSweepError::SpeedRange { v_min, v_max });
            }
            if per_decade == 0 || per_decade > MAX_SPEEDS as u32 {
                return Err(FrictionSweepError::PerDecade(per_decade));
            }
            let n = per_decade as f64;
            let k = (n * (v_max / v_min).log10()).round();
            if k + 1.0 > MAX_SPEEDS as f64 {
                return Err(FrictionSweepError::TooManySpeeds { count: k + 1.0, v_min, v_max, per_decade });
            }
            let k = k as i32;
            (0..=k).map(|i| v_min * 10f64.powf(i as f64 / n)).collect()
        }
    };
    if v.is_empty() {
        return Err(FrictionSweepError::NoSpeed);
    }
    if let Some(bad) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(FrictionSweepError::BadSpeed(*bad));
    }
    v.sort_by(|a, b| a.total_cmp(b));
    if let Some(w) = v.windows(2).find(|w| w[1] <= w[0]) {
        return Err(FrictionSweepError::RepeatedSpeed(w[0]));
    }
    Ok(v)
}

/// Length (s) of the sampled window of a friction-sweep pass at speed v (m/s) over [start, end] (m) with
/// acceleration a (m/s²): min(duration, T_c − settle), T_c = (end − start − v²/a)/v the cruise time left
/// after the two ramps of v²/(2a). Errors when fewer than 10 samples at `rate` (Hz) would remain, so
/// the caller lowers the speed, widens the travel or shortens `settle`.
#[allow(clippy::too_many_arguments)]
pub fn friction_sweep_window(
    v: f64,
    start: f64,
    end: f64,
    a: f64,
    settle: f64,
    duration: f64,
    rate: f64,
) -> Result<f64, FrictionSweepError> {
    for (key, value) in [("start", start), ("end", end), ("settle", settle), ("duration", duration), ("rate", rate)] {
        if !value.is_finite() {
            return Err(FrictionSweepError::NotFinite { key, value });
        }
    }
    if !(end > start && a > 0.0 && settle >= 0.0 && duration > 0.0 && rate > 0.0 && v > 0.0) {
        return Err(FrictionSweepError::Window { start, end, accel: a, settle, duration, rate, speed: v });
    }
    let cruise = (end - start - v * v / a) / v;
    let window = duration.min(cruise - settle);
    if window * rate < 10.0 {
        return Err(FrictionSweepError::ShortCruise {
            speed: v,
            start,
            end,
            cruise_left: cruise - settle,
            settle,
            accel: a,
            rate,
        });
    }
    Ok(window)
}

impl ProcedureSpec {
    /// Checks what the simulation of this procedure needs beyond the scenario's checks (FrictionSweep: its
    /// speeds, and a steady window at every speed within [start, end] at the axis's max_accel; every
    /// speed ≤ the axis's max_feed). Other procedures: Ok.
    /// The size of the procedure before it is planned (DESIGN.md §2 size budget): every key that sets a
    /// count or a duration checked finite and within its limit, every sampling rate ≤ 1/dt (one sample
    /// per physics step at most), and the estimated number of recorded samples (Σ rate·window) and
    /// physics steps (machine time / dt). Returns the key and message of the first problem, else
    /// (samples, steps). `dt` is the physics step (s), `max_accel` the axis's (m/s², > 0): a move at
    /// feed v takes v/a longer than distance/v (issue 14: a max_accel of 1e-300 hung the simulation
    /// in its first run-up, which the budget did not count).
    pub fn budget(&self, dt: f64, max_accel: f64) -> Result<(f64, f64), (String, String)> {
        fn err<T>(k: &str, m: String) -> Result<T, (String, String)> {
            Err((k.to_string(), m))
        }
        let time_key = |k: &str, v: f64, positive: bool| -> Result<(), (String, String)> {
            if v.is_finite() && v <= MAX_SECONDS && (v > 0.0 || !positive && v >= 0.0) {
                Ok(())
            } else {
                let sign = if positive { "> 0" } else { "≥ 0" };
                err(k, format!("expected a time {sign} and ≤ {MAX_SECONDS:e} s, got {v}"))
            }
        };
        let rate_key = |k: &str, r: f64| -> Result<(), (String, String)> {
            if r.is_finite() && r > 0.0 && r * dt <= 1.0 + 1e-9 {
                Ok(())
            } else {
                err(k, format!("expected a sampling rate > 0 and ≤ 1/dt = {} Hz (dt = {dt} s), got {r}", 1.0 / dt))
            }
        };
        let count = |k: &str, n: f64, limit: usize| -> Result<(), (String, String)> {
            if n.is_finite() && n <= limit as f64 {
                Ok(())
            } else {
                err(k, format!("this makes {n} {k}; the limit is {limit}"))
            }
        };
        let span = |start: f64, end: f64| (end - start).abs();
        let (samples, time) = match self {
            ProcedureSpec::ConstantVelocity { speeds, start, end, high_rate, settle, .. } => {
                rate_key("high_rate", *high_rate)?;
                time_key("settle", *settle, false)?;
                count("speeds", speeds.len() as f64, MAX_SPEEDS)?;
                let vmax = speeds.iter().cloned().fold(0.0, f64::max);
                let per_pass = high_rate * span(*start, *end) / vmax;
                // Each pass runs up over v²/(2a) + v·settle and back: 2·(2·v/a + settle) more than the span.
                let time: f64 = speeds
                    .iter()
                    .map(|v| settle + 2.0 * span(*start, *end) / v + 4.0 * v / max_accel + 2.0 * settle)
                    .sum();
                count("samples", per_pass * speeds.len() as f64, MAX_SAMPLES)?;
                (per_pass * speeds.len() as f64, time)
            }
            ProcedureSpec::Positioning(p) => {
                if p.accel.is_some_and(|a| !(a.is_finite() && a > 0.0)) {
                    return err("accel", format!("expected an acceleration > 0 m/s², got {:?}", p.accel));
                }
                let n = p.targets.as_ref().map_or(p.n_targets, Vec::len) as f64;
                count("n_targets", n, MAX_TARGETS)?;
                count("runs", p.runs as f64, MAX_RUNS)?;
                count("targets × runs", n * p.runs as f64, MAX_VISITS)?;
                time_key("dwell", p.dwell, true)?;
                time_key("average", p.average, true)?;
                rate_key("rate", p.rate)?;
                let visits = 2.0 * n * p.runs as f64;
                let travel = 2.0 * p.runs as f64 * (span(p.start, p.end) + 2.0 * p.overrun.abs()) / p.feed;
                // One move per visit and two overrun moves per run, each v/a longer than its distance/v.
                let ramps = (visits + 2.0 * p.runs as f64) * p.feed / p.accel.unwrap_or(max_accel);
                (visits * (p.average * p.rate + 1.0), visits * p.dwell + travel + ramps)
            }
            ProcedureSpec::Crawl { feeds, start: _, duration, rate, settle, .. } => {
                time_key("duration", *duration, true)?;
                time_key("settle", *settle, false)?;
                rate_key("rate", *rate)?;
                count("feeds", feeds.len() as f64, MAX_SPEEDS)?;
                let k = feeds.len() as f64;
                let ramps: f64 = feeds.iter().map(|v| 2.0 * v / max_accel).sum();
                (k * rate * duration, k * (settle + duration + 1.0) + ramps)
            }
            ProcedureSpec::NineLine { start, end, step, feed, dwell, average, rate, overrun, .. } => {
                let n = span(*start, *end) / step + 1.0;
                if step.is_nan() || *step < 1e-9 {
                    return err("step", format!("expected a step ≥ 1e-9 m (the targets' 1 nm grid), got {step}"));
                }
                count("n_targets", n, MAX_TARGETS)?;
                time_key("dwell", *dwell, true)?;
                time_key("average", *average, true)?;
                rate_key("rate", *rate)?;
                let travel = 2.0 * (span(*start, *end) + 2.0 * overrun.abs()) / feed;
                let ramps = (2.0 * n + 2.0) * feed / max_accel;
                (2.0 * n * (average * rate + 1.0), 2.0 * n * dwell + travel + ramps)
            }
            ProcedureSpec::FrictionSweep { speeds, v_min, v_max, per_decade, settle, duration, rate, .. } => {
                time_key("settle", *settle, false)?;
                time_key("duration", *duration, true)?;
                rate_key("rate", *rate)?;
                if let Some(v) = speeds {
                    count("speeds", v.len() as f64, MAX_SPEEDS)?;
                }
                let v = friction_sweep_speeds(speeds.as_deref(), *v_min, *v_max, *per_decade)
                    .map_err(|e| ("speeds".to_string(), e.to_string()))?;
                let n = v.len() as f64;
                let ramps: f64 = v.iter().map(|v| 4.0 * v / max_accel).sum();
                (2.0 * n * rate * duration, 2.0 * n * (0.5 + settle + duration + 1.0) + ramps)
            }
            ProcedureSpec::Pause { duration, .. } => {
                time_key("duration", *duration, false)?;
                (0.0, 0.0)
            }
        };
        count("samples", samples, MAX_SAMPLES)?;
        let steps = time / dt;
        if steps.is_nan() || steps > MAX_STEPS {
            return err(
                "",
                format!(
                    "the procedure needs about {steps:.3e} physics steps ({time:.4e} s of machine time at dt = {dt} s \
                     and axis.max_accel = {} m/s², from its speeds, accelerations, distances, dwells, runs \
                     and durations); the limit is {MAX_STEPS:e}",
                    crate::effects::fmt_num(max_accel)
                ),
            );
        }
        Ok((samples, steps))
    }

    /// Checks what can only be checked against the axis (a friction sweep's speeds within the axis's
    /// max feed, and a sample window the travel allows at each speed); the message says what failed.
    pub fn check(&self, model: &AxisModel) -> Result<(), FrictionSweepError> {
        if let ProcedureSpec::FrictionSweep {
            speeds,
            v_min,
            v_max,
            per_decade,
            start,
            end,
            settle,
            duration,
            rate,
            ..
        } = self
        {
            for v in friction_sweep_speeds(speeds.as_deref(), *v_min, *v_max, *per_decade)? {
                if v > model.max_feed * (1.0 + 1e-9) {
                    return Err(FrictionSweepError::AboveMaxFeed { speed: v, max_feed: model.max_feed });
                }
                friction_sweep_window(v, *start, *end, model.max_accel, *settle, *duration, *rate)?;
            }
        }
        Ok(())
    }

    /// The procedure's name (the prefix of its run names).
    pub fn name(&self) -> &str {
        match self {
            ProcedureSpec::ConstantVelocity { name, .. }
            | ProcedureSpec::Positioning(PositioningSpec { name, .. })
            | ProcedureSpec::Crawl { name, .. }
            | ProcedureSpec::NineLine { name, .. }
            | ProcedureSpec::FrictionSweep { name, .. }
            | ProcedureSpec::Pause { name, .. } => name,
        }
    }

    /// Names of the sensors the procedure reads (none for a pause).
    pub fn sensors(&self) -> &[String] {
        match self {
            ProcedureSpec::ConstantVelocity { sensors, .. }
            | ProcedureSpec::Positioning(PositioningSpec { sensors, .. })
            | ProcedureSpec::Crawl { sensors, .. }
            | ProcedureSpec::NineLine { sensors, .. }
            | ProcedureSpec::FrictionSweep { sensors, .. } => sensors,
            ProcedureSpec::Pause { .. } => &[],
        }
    }
}

/// One reading of a point table: an approach to a target.
#[derive(Clone, Debug, PartialEq)]
pub struct Visit {
    /// Target position, m.
    pub target: f64,
    /// Run (cycle) number, 1..=runs.
    pub run: u32,
    /// Approach direction: +1 from below, −1 from above.
    pub direction: i8,
    /// Index into the trace of the averaging window's first sample.
    pub first: usize,
    /// Index into the trace of the averaging window's last sample (inclusive).
    pub last: usize,
}

/// How a run's samples are laid out.
#[derive(Clone, Debug, PartialEq)]
pub enum Layout {
    /// Uniform samples at `rate` Hz; the trace holds one extra leading sample (accelerometers average
    /// over the interval before each output sample).
    TimeSeries {
        /// Sample rate, Hz.
        rate: f64,
    },
    /// One row per visit (approach to a target), averaged over the visit's window.
    PointTable {
        /// The visits in time order.
        visits: Vec<Visit>,
    },
}

/// The noise-free truth of one run.
#[derive(Clone, Debug)]
pub struct RunTruth {
    /// Run name (unique in the measurement set).
    pub name: String,
    /// The procedure kind, the manifest's `procedure`.
    pub procedure: ProcedureKind,
    /// Feed of a constant-velocity, crawl or sweep run, m/s; `None` for a positioning run.
    pub feed: Option<f64>,
    /// Direction of a one-way run (+1 up, −1 down); `None` for a bidirectional run.
    pub direction: Option<i8>,
    /// Start of the run on the session clock, s (time-dependent effects run on it).
    pub start_time: f64,
    /// Names of the sensors that record the run.
    pub sensors: Vec<String>,
    /// Time series or point table, with the sample windows.
    pub layout: Layout,
    /// Noise-free samples at the plan's record times.
    pub samples: Vec<Sample>,
}

/// The column of a single-axis time series that holds the commanded position along the axis, m
/// (FORMAT.md §1: `x_cmd`, the axis's own coordinate; a chain's lines write one per axis).
pub const COMMAND_COLUMN: &str = "x_cmd";

/// A run's data as a measurement set holds it (FORMAT.md §1), SI units. Time series: `t` then
/// columns ([`COMMAND_COLUMN`] and sensors). Point table (positioning): `target`, `run` (1..n), `direction`
/// (+1/−1), optional `t`, then the sensors' deviations or readings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum RunData {
    /// Samples at increasing times.
    TimeSeries {
        /// Time of each sample, s, increasing.
        t: Vec<f64>,
        /// (name, values) per column: `x_cmd` (m) and the sensors, SI units, one value per sample.
        columns: Vec<(String, Vec<f64>)>,
    },
    /// One row per approach to a target (positioning).
    PointTable {
        /// Target position of each row, m.
        target: Vec<f64>,
        /// Run (cycle) number of each row, 1..=n.
        run: Vec<u32>,
        /// Approach direction of each row, +1 / −1.
        direction: Vec<i8>,
        /// Time of each reading, s, where recorded (for drift).
        t: Option<Vec<f64>>,
        /// (name, values) per sensor: deviations (actual − target) or readings, SI units, one per row.
        columns: Vec<(String, Vec<f64>)>,
    },
}

impl RunData {
    /// Number of rows.
    pub fn len(&self) -> usize {
        match self {
            RunData::TimeSeries { t, .. } => t.len(),
            RunData::PointTable { target, .. } => target.len(),
        }
    }

    /// Whether the run has no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The data columns (sensors, and `x_cmd` for a time series).
    pub fn columns(&self) -> &[(String, Vec<f64>)] {
        match self {
            RunData::TimeSeries { columns, .. } | RunData::PointTable { columns, .. } => columns,
        }
    }

    /// A column by name.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns().iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }

    /// The commanded position of a single-axis time series ([`COMMAND_COLUMN`]), m.
    pub fn command(&self) -> Option<&[f64]> {
        self.column(COMMAND_COLUMN)
    }

    /// The time column, if any.
    pub fn t(&self) -> Option<&[f64]> {
        match self {
            RunData::TimeSeries { t, .. } => Some(t),
            RunData::PointTable { t, .. } => t.as_deref(),
        }
    }
}

/// A run as measured: metadata and data.
#[derive(Clone, Debug, PartialEq)]
pub struct RunRecord {
    /// Run name (unique in the measurement set).
    pub name: String,
    /// The procedure kind, the manifest's `procedure`.
    pub procedure: ProcedureKind,
    /// Feed of a constant-velocity, crawl or sweep run, m/s; `None` for a positioning run.
    pub feed: Option<f64>,
    /// Direction of a one-way run (+1 up, −1 down); `None` for a bidirectional run.
    pub direction: Option<i8>,
    /// Start of the run on the session clock, s (time-dependent effects run on it).
    pub start_time: f64,
    /// The recorded columns.
    pub data: RunData,
}

/// Irregular ISO 230-2 targets: n targets from start to end, interior ones shifted by a seeded random
/// fraction (±0.3) of the interval so that periodic errors are not sampled at one phase.
pub fn irregular_targets(start: f64, end: f64, n: usize, seed: u64, name: &str) -> Vec<f64> {
    let mut rng = source_rng(seed, &format!("{name}/targets"));
    let p = (end - start) / (n.max(2) - 1) as f64;
    (0..n)
        .map(|i| {
            let base = start + p * i as f64;
            if i == 0 || i + 1 == n {
                base
            } else {
                base + p * 0.3 * (2.0 * rng.gen::<f64>() - 1.0)
            }
        })
        .map(|x| (x * 1e6).round() / 1e6)
        .collect()
}

/// Ticks per second of the recorder's clock: every record time and session start is a whole number of
/// nanoseconds.
pub const RECORD_CLOCK_HZ: f64 = 1e9;

/// A time (s) on the recorder's clock: t' = round(t·f_c)/f_c with f_c = [`RECORD_CLOCK_HZ`], the double
/// nearest to a whole number of nanoseconds (|t' − t| ≤ 0.5 ns). The plan's times are sums of segment
/// durations and carry their rounding (22.480000000000004 s); the simulator samples the truth at t', so a
/// written time is the exact time of its sample and reads as the decimal it is (22.48 s).
pub fn recorder_time(t: f64) -> f64 {
    (t * RECORD_CLOCK_HZ).round() / RECORD_CLOCK_HZ
}

/// The commanded motion of one run and the times at which its truth is recorded (run time, s), before
/// any physics: what a procedure asks of the machine.
#[derive(Clone, Debug)]
pub struct RunPlan {
    /// Run name (unique in the measurement set).
    pub name: String,
    /// The procedure kind, the manifest's `procedure`.
    pub procedure: ProcedureKind,
    /// Feed of a constant-velocity, crawl or sweep run, m/s; `None` for a positioning run.
    pub feed: Option<f64>,
    /// Direction of a one-way run (+1 up, −1 down); `None` for a bidirectional run.
    pub direction: Option<i8>,
    /// Names of the sensors that record the run.
    pub sensors: Vec<String>,
    /// Time series or point table, with the sample windows.
    pub layout: Layout,
    /// Commanded motion, run time from 0.
    pub plan: MotionPlan,
    /// Times at which the truth is recorded, run time, s, increasing, on the recorder's clock
    /// ([`recorder_time`]).
    pub record_times: Vec<f64>,
}

impl RunPlan {
    /// How long the run occupies the machine, s: the end of its motion plan or its last recorded
    /// sample, whichever is later.
    pub fn duration(&self) -> f64 {
        self.plan.end_time().max(self.record_times.last().copied().unwrap_or(0.0))
    }
}

/// Session start time of each run when the runs follow one another without a pause, in order, the
/// first starting at `t0` (s): start_k = t0 + Σ_{i<k} duration_i. This is the session clock that
/// time-dependent effects (thermal expansion, thermal drift) are evaluated on, so that they carry
/// over from one run to the next, as on a real machine warming up during a measurement session. Each
/// start is on the recorder's clock ([`recorder_time`]), as the manifest's `start_time` writes it.
pub fn session_schedule(runs: &[RunPlan], t0: f64) -> Vec<f64> {
    runs.iter()
        .scan(t0, |t, r| {
            let start = recorder_time(*t);
            *t += r.duration();
            Some(start)
        })
        .collect()
}

/// The runs of a measurement session, each with its session start time (s): the procedures in order,
/// their runs back to back from t = 0 ([`session_schedule`]), a [`ProcedureSpec::Pause`] advancing the
/// clock by its duration.
pub fn plan_session(model: &AxisModel, procedures: &[ProcedureSpec], seed: u64) -> Vec<(RunPlan, f64)> {
    let mut clock = 0.0;
    let mut out = Vec::new();
    for p in procedures {
        if let ProcedureSpec::Pause { duration, .. } = p {
            clock += duration;
            continue;
        }
        let runs = plan_procedure(model, p, seed);
        let starts = session_schedule(&runs, clock);
        clock = runs.last().zip(starts.last()).map_or(clock, |(r, t0)| t0 + r.duration());
        out.extend(runs.into_iter().zip(starts));
    }
    out
}

/// Simulates one run starting at session time `start_time` (s) and returns its noise-free truth.
pub fn simulate_run(model: &AxisModel, truth: &AxisTruth, run: &RunPlan, start_time: f64) -> RunTruth {
    RunTruth {
        name: run.name.clone(),
        procedure: run.procedure,
        feed: run.feed,
        direction: run.direction,
        start_time,
        sensors: run.sensors.clone(),
        layout: run.layout.clone(),
        samples: simulate_in_session(model, truth, &run.plan, &run.record_times, start_time).samples,
    }
}

/// Simulates a procedure whose first run starts at session time 0, the others following it without
/// a pause ([`session_schedule`]); returns one truth per run. A friction sweep that fails
/// [`ProcedureSpec::check`] yields no runs (check it first: the scenario loader does).
pub fn simulate_procedure(model: &AxisModel, errors: &AxisTruth, spec: &ProcedureSpec, seed: u64) -> Vec<RunTruth> {
    let runs = plan_procedure(model, spec, seed);
    let starts = session_schedule(&runs, 0.0);
    runs.iter().zip(starts).map(|(r, t0)| simulate_run(model, errors, r, t0)).collect()
}

/// The runs of a procedure as commanded motions and record times (no physics). A friction sweep that
/// fails [`ProcedureSpec::check`], and a pause, yield no runs.
pub fn plan_procedure(model: &AxisModel, spec: &ProcedureSpec, seed: u64) -> Vec<RunPlan> {
    let time_series = |name: String, procedure, v: f64, direction: i8, rate: f64, plan, times: Vec<f64>| RunPlan {
        name,
        procedure,
        feed: Some(v),
        direction: Some(direction),
        sensors: spec.sensors().to_vec(),
        layout: Layout::TimeSeries { rate },
        plan,
        record_times: times.into_iter().map(recorder_time).collect(),
    };
    match spec {
        ProcedureSpec::ConstantVelocity { name, speeds, start, end, high_rate, direction, settle, .. } => {
            let vmax = speeds.iter().cloned().fold(0.0, f64::max);
            // index: every count below comes from keys the scenario checked before planning (ProcedureSpec::budget:
            // rates ≤ 1/dt, times ≤ MAX_SECONDS, samples ≤ MAX_SAMPLES, targets ≤ MAX_TARGETS; validate_procedures:
            // finite start/end/step).
            let n = (high_rate * (end - start).abs() / vmax).round() as usize;
            let labels: Vec<String> = if speeds.len() == 3 {
                ["low", "mid", "high"].iter().map(|s| format!("{name}_{s}")).collect()
            } else {
                (1..=speeds.len()).map(|i| format!("{name}_{i}")).collect()
            };
            let mut sorted: Vec<f64> = speeds.clone();
            sorted.sort_by(f64::total_cmp);
            let d: i8 = if *direction >= 0 { 1 } else { -1 };
            sorted
                .iter()
                .zip(labels)
                .map(|(&v, label)| {
                    let rate = high_rate * v / vmax;
                    let (from, to) = if d > 0 { (*start, *end) } else { (*end, *start) };
                    let s = (to - from).signum();
                    let ramp = v * v / (2.0 * model.max_accel) + v * settle;
                    let mut plan = MotionPlan::starting_at(from - s * ramp);
                    plan.dwell(0.3);
                    let (t0, _) = plan.move_to(to + s * ramp, v, model.max_accel);
                    let t_first = t0 + v / model.max_accel + settle;
                    let times: Vec<f64> = (0..=n).map(|i| t_first + (i as f64 - 1.0) / rate).collect();
                    time_series(label, ProcedureKind::ConstantVelocity, v, d, rate, plan, times)
                })
                .collect()
        }
        ProcedureSpec::Positioning(p) => {
            let targets =
                p.targets.clone().unwrap_or_else(|| irregular_targets(p.start, p.end, p.n_targets, seed, &p.name));
            let a = p.accel.unwrap_or(model.max_accel);
            let cycle =
                Cycle { runs: p.runs, feed: p.feed, accel: a, dwell: p.dwell, average: p.average, rate: p.rate };
            vec![positioning_cycle(&p.name, &targets, &cycle, p.overrun, &p.sensors)]
        }
        ProcedureSpec::Crawl { name, feeds, start, duration, rate, settle, direction, .. } => feeds
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let s: i8 = if *direction >= 0 { 1 } else { -1 };
                let mut plan = MotionPlan::starting_at(*start);
                plan.dwell(0.2);
                let (t0, _) = plan.move_to(start + f64::from(s) * v * (settle + duration + 1.0), v, model.max_accel);
                let t_first = t0 + v / model.max_accel + settle;
                let n = (duration * rate).round() as usize;
                let times: Vec<f64> = (0..=n).map(|k| t_first + (k as f64 - 1.0) / rate).collect();
                time_series(format!("{name}_{}", i + 1), ProcedureKind::Crawl, v, s, *rate, plan, times)
            })
            .collect(),
        ProcedureSpec::NineLine { name, start, end, step, feed, dwell, average, rate, overrun, .. } => {
            let n = ((end - start) / step).round() as usize;
            // On a 1 nm grid (a CNC commands a target on its position grid; `budget` refuses a step below
            // 1 nm): start + step·i carries the sum's rounding (0.30000000000000004 m).
            let targets: Vec<f64> = (0..=n).map(|i| ((start + step * i as f64) * 1e9).round() / 1e9).collect();
            let cycle =
                Cycle { runs: 1, feed: *feed, accel: model.max_accel, dwell: *dwell, average: *average, rate: *rate };
            vec![positioning_cycle(name, &targets, &cycle, *overrun, spec.sensors())]
        }
        ProcedureSpec::FrictionSweep {
            name,
            speeds,
            v_min,
            v_max,
            per_decade,
            start,
            end,
            settle,
            duration,
            rate,
            ..
        } => {
            if spec.check(model).is_err() {
                return Vec::new();
            }
            let speeds = friction_sweep_speeds(speeds.as_deref(), *v_min, *v_max, *per_decade).unwrap_or_default();
            let a = model.max_accel;
            let mut out = Vec::with_capacity(2 * speeds.len());
            for (i, &v) in speeds.iter().enumerate() {
                let Ok(window) = friction_sweep_window(v, *start, *end, a, *settle, *duration, *rate) else {
                    return Vec::new();
                };
                for s in [1i8, -1] {
                    let from = if s > 0 { *start } else { *end };
                    let mut plan = MotionPlan::starting_at(from);
                    // The body settles on its bearings at rest first (their rocking moves the reference point).
                    plan.dwell(0.5);
                    // Ramp v²/(2a), cruise settle + window (+ one sample period), ramp down.
                    let length = v * v / a + v * (settle + window + 1.0 / rate);
                    let (t0, _) = plan.move_to(from + f64::from(s) * length, v, a);
                    let t_first = t0 + v / a + settle;
                    let n = (window * rate).round() as usize;
                    let times: Vec<f64> = (0..=n).map(|k| t_first + k as f64 / rate).collect();
                    let label = format!("{name}_{}_{}", i + 1, if s > 0 { "pos" } else { "neg" });
                    out.push(time_series(label, ProcedureKind::FrictionSweep, v, s, *rate, plan, times));
                }
            }
            out
        }
        ProcedureSpec::Pause { .. } => Vec::new(),
    }
}

/// How a positioning cycle moves and reads: `runs` bidirectional runs at `feed` (m/s) and `accel`
/// (m/s²), a `dwell` (s) at each target whose last `average` s are read at `rate` (Hz).
struct Cycle {
    runs: u32,
    feed: f64,
    accel: f64,
    dwell: f64,
    average: f64,
    rate: f64,
}

/// ISO 230-2 linear cycle: for each run, approach every target upwards (from below the first target by
/// `overrun`), then every target downwards (from above the last by `overrun`).
fn positioning_cycle(name: &str, targets: &[f64], c: &Cycle, overrun: f64, sensors: &[String]) -> RunPlan {
    // index: ≥ 2 targets (validate_procedures: explicit targets; irregular_targets with n_targets ≥ 2), and
    // average·rate is bounded by the budget.
    let first = targets[0];
    let last = targets[targets.len() - 1];
    let mut plan = MotionPlan::starting_at(first - overrun);
    plan.dwell(0.3);
    let mut windows = Vec::new();
    let mut visits_meta = Vec::new();
    for run in 1..=c.runs {
        if run > 1 {
            plan.move_to(first - overrun, c.feed, c.accel);
        }
        for &x in targets {
            plan.move_to(x, c.feed, c.accel);
            let (_, t1) = plan.dwell(c.dwell);
            windows.push(t1);
            visits_meta.push((x, run, 1i8));
        }
        plan.move_to(last + overrun, c.feed, c.accel);
        for &x in targets.iter().rev() {
            plan.move_to(x, c.feed, c.accel);
            let (_, t1) = plan.dwell(c.dwell);
            windows.push(t1);
            visits_meta.push((x, run, -1i8));
        }
    }
    let per = ((c.average * c.rate).round() as usize).max(1);
    let mut times = Vec::with_capacity(windows.len() * per);
    let mut visits = Vec::with_capacity(windows.len());
    for (t1, (target, run, direction)) in windows.iter().zip(visits_meta) {
        let first = times.len();
        for k in 0..per {
            times.push(recorder_time(t1 - (per - 1 - k) as f64 / c.rate));
        }
        visits.push(Visit { target, run, direction, first, last: times.len() - 1 });
    }
    RunPlan {
        name: name.to_string(),
        procedure: ProcedureKind::Positioning,
        feed: Some(c.feed),
        direction: None,
        sensors: sensors.to_vec(),
        layout: Layout::PointTable { visits },
        plan,
        record_times: times,
    }
}

/// Reads the sensors of a run from its truth with noise seeded by (seed, "run/sensor").
///
/// Time series: one reading per sample. Point tables: per visit, the noise-free reading averaged over
/// the dwell's averaging window, then the sensor's errors and noise applied once per reading (a
/// sensor's `sigma` is the 1σ of one reading); lasers and encoders hold the deviation actual − target
/// along their direction.
pub fn read_run(
    model: &AxisModel,
    physics: &AxisTruth,
    truth: &RunTruth,
    sensors: &[SensorSpec],
    seed: u64,
) -> Result<RunRecord, SensorError> {
    read_run_clean(model, truth, sensors, seed, &clean_run(model, physics, truth, sensors)?)
}

/// The sensor declared under `name`, resolved (its preset's values filled in).
fn declared(truth: &RunTruth, sensors: &[SensorSpec], name: &str) -> Result<SensorSpec, SensorError> {
    sensors
        .iter()
        .find(|s| s.name == name)
        .map(SensorSpec::resolved)
        .ok_or_else(|| SensorError::Undeclared { run: truth.name.clone(), sensor: name.to_string() })
}

/// The noise-free readings ([`true_readings`]) of every sensor of a run, in the order of
/// `truth.sensors`: what [`read_run_clean`] applies each trial's errors and noise to. They depend on the
/// sensors' kind, mounting and direction, not on their noise, so a study whose trials share the physics and
/// the sensors computes them once.
pub fn clean_run(
    model: &AxisModel,
    physics: &AxisTruth,
    truth: &RunTruth,
    sensors: &[SensorSpec],
) -> Result<Vec<Vec<f64>>, SensorError> {
    truth
        .sensors
        .iter()
        .map(|name| true_readings(&declared(truth, sensors, name)?, model, physics.mode.as_ref(), &truth.samples))
        .collect()
}

/// [`read_run`] from the run's noise-free readings `clean` ([`clean_run`] of the same truth and sensors).
pub fn read_run_clean(
    model: &AxisModel,
    truth: &RunTruth,
    sensors: &[SensorSpec],
    seed: u64,
    clean: &[Vec<f64>],
) -> Result<RunRecord, SensorError> {
    let mut columns = Vec::new();
    for (name, clean) in truth.sensors.iter().zip(clean) {
        let spec = declared(truth, sensors, name)?;
        let mut rng = source_rng(seed, &format!("{}/{}", truth.name, spec.name));
        let values = match &truth.layout {
            Layout::TimeSeries { rate } => apply_errors(&spec, &clean[1..], *rate, &mut rng),
            Layout::PointTable { visits } => {
                let means = visit_means(&spec, model, clean, visits);
                let window = visits.first().map_or(1.0, |a| (a.last - a.first + 1) as f64);
                apply_errors(&spec, &means, sample_rate(&truth.samples) / window, &mut rng)
            }
        };
        columns.push((spec, values));
    }
    let data = match &truth.layout {
        Layout::TimeSeries { .. } => {
            let t: Vec<f64> = truth.samples[1..].iter().map(|s| s.t).collect();
            let x_cmd = columns
                .iter()
                .find(|(s, _)| s.kind == SensorKind::Command)
                .map(|(_, v)| v.clone())
                .unwrap_or_else(|| truth.samples[1..].iter().map(|s| s.cmd.pos).collect());
            let mut cols = vec![(COMMAND_COLUMN.to_string(), x_cmd)];
            cols.extend(columns.into_iter().filter(|(s, _)| s.kind != SensorKind::Command).map(|(s, v)| (s.name, v)));
            RunData::TimeSeries { t, columns: cols }
        }
        Layout::PointTable { visits } => RunData::PointTable {
            target: visits.iter().map(|a| a.target).collect(),
            run: visits.iter().map(|a| a.run).collect(),
            direction: visits.iter().map(|a| a.direction).collect(),
            t: Some(visits.iter().map(|a| truth.samples[a.last].t).collect()),
            columns: columns
                .into_iter()
                .filter(|(s, _)| s.kind != SensorKind::Command)
                .map(|(s, v)| (s.name, v))
                .collect(),
        },
    };
    Ok(RunRecord {
        name: truth.name.clone(),
        procedure: truth.procedure,
        feed: truth.feed,
        direction: truth.direction,
        start_time: truth.start_time,
        data,
    })
}

/// Noise-free point-table values of a (resolved) sensor: per visit, the mean of its true reading `clean`
/// (one value per sample) over the visit's averaging window, less the nominal reading at the target —
/// the deviation (m) a noiseless instrument would write in the row.
fn visit_means(spec: &SensorSpec, model: &AxisModel, clean: &[f64], visits: &[Visit]) -> Vec<f64> {
    let nominal = |target: f64| match spec.kind {
        SensorKind::EncoderLinear | SensorKind::EncoderRotary => target,
        SensorKind::LaserLinear | SensorKind::LaserStraightness | SensorKind::LaserVector => {
            spec.unit_direction().dot(model.axis) * target
        }
        // An angle, an acceleration, a force or an air reading: no nominal displacement.
        SensorKind::Command
        | SensorKind::LaserAngular
        | SensorKind::Accelerometer
        | SensorKind::MotorForce
        | SensorKind::Velocity
        | SensorKind::Temperature
        | SensorKind::Pressure
        | SensorKind::Humidity => 0.0,
    };
    visits
        .iter()
        .map(|a| clean[a.first..=a.last].iter().sum::<f64>() / (a.last - a.first + 1) as f64 - nominal(a.target))
        .collect()
}

/// The noise-free point table of sensor `name` in the positioning run `truth` (one value per row, in the
/// row order [`read_run`] writes): what the instrument would read without noise, quantisation or bias —
/// the truth an ISO 230-2 evaluation of the recorded table estimates, whatever the physics put on the
/// table at rest (error motions, feedback chain, lead error, backlash, the screw's windup, settling).
/// `Ok(None)` for a time series or a sensor the run does not record.
pub fn noise_free_point_table(
    model: &AxisModel,
    physics: &AxisTruth,
    truth: &RunTruth,
    sensors: &[SensorSpec],
    name: &str,
) -> Result<Option<Vec<f64>>, SensorError> {
    let Layout::PointTable { visits } = &truth.layout else { return Ok(None) };
    if !truth.sensors.iter().any(|s| s == name) {
        return Ok(None);
    }
    let Some(spec) = sensors.iter().find(|s| s.name == name) else { return Ok(None) };
    let spec = spec.resolved();
    let clean = true_readings(&spec, model, physics.mode.as_ref(), &truth.samples)?;
    Ok(Some(visit_means(&spec, model, &clean, visits)))
}

/// Sample rate of the averaging windows of a point table (from the first two samples), Hz.
fn sample_rate(samples: &[Sample]) -> f64 {
    match samples {
        [a, b, ..] if b.t > a.t => 1.0 / (b.t - a.t),
        _ => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn record_times_are_whole_nanoseconds_without_the_sums_rounding() {
        let noisy = 0.9 + 21.58;
        assert_ne!(noisy, 22.48);
        assert_eq!(recorder_time(noisy), 22.48);
        assert_eq!(recorder_time(0.625 + 72.0 / 400.0), 0.805);
        assert!((recorder_time(1.0 / 3.0) - 1.0 / 3.0).abs() <= 0.5e-9);
    }

    #[test]
    fn sweep_speeds_are_log_spaced_and_bad_ones_rejected() {
        // 2 per decade over 4 decades: 9 speeds, 1e-5 · 10^(k/2).
        let v = friction_sweep_speeds(None, 1e-5, 0.1, 2).unwrap();
        assert_eq!(v.len(), 9);
        assert!((v[1] / 1e-5 - 10f64.sqrt()).abs() < 1e-12 && (v[8] / 0.1 - 1.0).abs() < 1e-12);
        assert_eq!(friction_sweep_speeds(Some(&[0.2, 0.01]), 0.0, 0.0, 0).unwrap(), vec![0.01, 0.2]);
        assert!(friction_sweep_speeds(None, 0.1, 1e-5, 2).unwrap_err().to_string().contains("v_min < v_max"));
        assert!(friction_sweep_speeds(None, f64::NAN, 0.1, 2).is_err());
        assert!(friction_sweep_speeds(None, 1e-5, 0.1, 0).is_err());
        assert!(friction_sweep_speeds(Some(&[0.1, -0.1]), 0.0, 0.0, 0).unwrap_err().to_string().contains("> 0"));
        assert!(friction_sweep_speeds(Some(&[0.1, 0.1]), 0.0, 0.0, 0).unwrap_err().to_string().contains("distinct"));
    }

    #[test]
    fn sweep_window_shrinks_at_high_speed_and_fails_when_the_travel_is_too_short() {
        // Slow: the full duration. 0.5 m/s over 0.8 m at 2 m/s²: cruise (0.8 − 0.125)/0.5 = 1.35 s,
        // minus 1 s settle leaves 0.35 s.
        assert_eq!(friction_sweep_window(1e-4, 0.1, 0.9, 2.0, 1.0, 0.5, 1000.0).unwrap(), 0.5);
        assert!((friction_sweep_window(0.5, 0.1, 0.9, 2.0, 1.0, 0.5, 1000.0).unwrap() - 0.35).abs() < 1e-12);
        assert!(friction_sweep_window(0.5, 0.1, 0.5, 2.0, 1.0, 0.5, 1000.0)
            .unwrap_err()
            .to_string()
            .contains("10 samples"));
        assert!(friction_sweep_window(0.1, 0.1, 0.9, 2.0, f64::NAN, 0.5, 1000.0).is_err());
    }
}
