//! Channels: the measurement set as stacked channels with per-sample sensitivities.

use super::command::{decimal_resolution, smooth_command, COMMAND_DEGREE};
use super::*;
use vmt_sim::effects::ErrorMotion;
use vmt_sim::procedures::COMMAND_COLUMN;
use vmt_sim::Axis;

// ------------------------------------------------------------------------------------------
// Channels.

/// One predicted channel: a deviation column of a point-table run, with the geometry of its sensor.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Channel {
    /// Run name.
    pub run: String,
    /// Sensor (column) name.
    pub sensor: String,
    /// Sensor kind.
    pub kind: SensorKind,
    /// Sensitive direction in the axis frame (unit vector).
    pub u: [f64; 3],
    /// Measuring point, axis frame, m.
    pub r: [f64; 3],
    /// Target positions x, m.
    pub x: Vec<f64>,
    /// Approach directions d = ±1.
    pub d: Vec<f64>,
    /// Run numbers (1..n).
    pub cycle: Vec<u32>,
    /// Times t, s since the start of the session (run start_time + the table's `t`).
    pub t: Vec<f64>,
    /// Velocity, m/s (the run's feed × direction for time series; 0 in point tables).
    pub v: Vec<f64>,
    /// Measured values: deviations (m) in point tables, motor force (N) in time series.
    pub y: Vec<f64>,
    /// 1σ noise from the manifest (None or 0 → estimated).
    pub sigma: Option<f64>,
    /// Encoder time series only: the transmission or following-error channel it is
    /// ([`encoder::EncoderRole`]); its `x` is then the measured position.
    pub encoder: Option<EncoderRole>,
}

impl Channel {
    /// Where the screw is at sample `i`, m: the motor encoder's reading on a transmission channel
    /// (scale − motor; a cyclic lead is a function of the screw's angle, and the scale reads the
    /// table, which stands apart from it by the play), else the channel's own position `x`.
    pub(crate) fn screw_x(&self, i: usize) -> f64 {
        match &self.encoder {
            Some(EncoderRole::Transmission { drive }) => drive[i],
            Some(EncoderRole::Following { .. }) | None => self.x[i],
        }
    }

    /// Sensitivity to the drive terms (backlash, cyclic lead): u·axis for a laser, 1 for a linear
    /// scale, 0 for a rotary encoder.
    pub(crate) fn s_drive(&self) -> f64 {
        if let Some(role) = &self.encoder {
            return role.s_transmission();
        }
        match self.kind {
            SensorKind::EncoderLinear => 1.0,
            SensorKind::LaserLinear | SensorKind::LaserStraightness | SensorKind::LaserVector => self.u[0],
            SensorKind::Command
            | SensorKind::EncoderRotary
            | SensorKind::LaserAngular
            | SensorKind::Accelerometer
            | SensorKind::MotorForce
            | SensorKind::Velocity
            | SensorKind::Temperature
            | SensorKind::Pressure
            | SensorKind::Humidity => 0.0,
        }
    }

    /// 1 for a motor-force channel (friction acts on it), 0 otherwise.
    pub(crate) fn s_force(&self) -> f64 {
        if self.kind == SensorKind::MotorForce {
            1.0
        } else {
            0.0
        }
    }

    /// Sensitivity to the feedback-chain terms (scale error, thermal, interpolation): u·axis for a
    /// laser, 0 for encoders (they read the chain itself).
    pub(crate) fn s_chain(&self) -> f64 {
        if let Some(role) = &self.encoder {
            return role.s_transmission();
        }
        if self.is_laser() {
            self.u[0]
        } else {
            0.0
        }
    }

    pub(crate) fn is_accel(&self) -> bool {
        self.kind == SensorKind::Accelerometer
    }

    pub(crate) fn is_laser(&self) -> bool {
        self.kind.is_laser_line()
    }

    /// Whether an error motion this channel sees is read as its value at the sample's position
    /// (a laser, an encoder), not as its slopes over the sample interval (an accelerometer):
    /// [`Channel::motion_read`].
    pub(crate) fn reads_values(&self) -> bool {
        self.is_laser() || self.encoder.is_some()
    }

    /// Sensitivity to error motion `name`: u_i for translations, (r × u)_i for rotations
    /// (u·(ε × r) = ε·(r × u)), for lasers (to the motion itself) and accelerometers (to its mean
    /// second derivative, see [`Channel::motion_response`]); 0 for encoders and motor forces.
    pub(crate) fn s_motion(&self, name: EffectName) -> f64 {
        // An encoder time series sees the screw's lead error (EXX) in its transmission.
        if let Some(role) = &self.encoder {
            return if name == EffectName::Positioning { role.s_transmission() } else { 0.0 };
        }
        if !self.is_laser() && !self.is_accel() {
            return 0.0;
        }
        let [ux, uy, uz] = self.u;
        let [rx, ry, rz] = self.r;
        let rxu = [ry * uz - rz * uy, rz * ux - rx * uz, rx * uy - ry * ux];
        match name.error_motion() {
            Some(ErrorMotion::Positioning) => ux,
            Some(ErrorMotion::StraightnessY) => uy,
            Some(ErrorMotion::StraightnessZ) => uz,
            Some(ErrorMotion::Roll) => rxu[0],
            Some(ErrorMotion::Pitch) => rxu[1],
            Some(ErrorMotion::Yaw) => rxu[2],
            None => 0.0,
        }
    }
}

/// How sample i of a channel reads an error motion's profile P ([`Channel::motion_read`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum MotionRead {
    /// Not at all (sensitivity 0, no interval, or no velocity).
    Blind,
    /// s·P(x): a laser or an encoder.
    Value { s: f64, x: f64 },
    /// s·v·(P'(xb) − P'(xa))/dt: an accelerometer's interval mean of v²·P'' (xa = xb − v·dt).
    SlopeDifference { s: f64, v: f64, dt: f64, xa: f64, xb: f64 },
}

impl Channel {
    /// How sample `i` reads an error motion `name`:
    ///
    /// ```text
    /// laser:          s·P(x_i)
    /// accelerometer:  s·v_i·(P'(x_i) − P'(x_i − v_i·Δt_i))/Δt_i = s·v_i²·P̄''(x_i − v_i·Δt_i, x_i)
    /// ```
    ///
    /// with s = [`Channel::s_motion`] (u_i or (r × u)_i). The accelerometer term is the guideway's
    /// acceleration of the measuring point at constant velocity v, d²/dt² u·(E + ε × r) = v²·u·(E'' +
    /// ε'' × r), averaged over the sample interval Δt_i (t_i − t_{i−1}; the first sample takes the
    /// second's) as the simulator's reading is (difference of point velocities at successive
    /// samples, `vmt_sim::sensors::true_readings`). Gravity through the angles (g·tilt) is not in
    /// it: that is the `gravity_tilt` effect.
    pub(crate) fn motion_read(&self, i: usize, name: EffectName) -> MotionRead {
        let s = self.s_motion(name);
        if s == 0.0 {
            return MotionRead::Blind;
        }
        if self.reads_values() {
            return MotionRead::Value { s, x: self.x[i] };
        }
        match self.interval_ends(i) {
            Some((xb, xa, v, dt)) => MotionRead::SlopeDifference { s, v, dt, xa, xb },
            None => MotionRead::Blind,
        }
    }

    /// Where the reference point moves over sample `i`'s window: (x_i, x_i − v·Δt, v in m/s, Δt
    /// in s; the window is the interval but at a gap, [`sample_window`]), what an accelerometer's
    /// sample reads a motion's slopes at ([`Channel::motion_read`]); None where it stands or the
    /// window is not positive.
    pub(crate) fn interval_ends(&self, i: usize) -> Option<(f64, f64, f64, f64)> {
        let dt = sample_window(self, i);
        let v = self.v[i];
        if !(dt > 0.0) || v == 0.0 {
            return None;
        }
        let xb = self.x[i];
        Some((xb, xb - v * dt, v, dt))
    }

    /// Response of sample `i` to an error motion `name` whose profile has value `value(x)` and slope
    /// `slope(x)` (first derivative in position), as [`Channel::motion_read`] says.
    pub(crate) fn motion_response(
        &self,
        i: usize,
        name: EffectName,
        value: impl Fn(f64) -> f64,
        slope: impl Fn(f64) -> f64,
    ) -> f64 {
        match self.motion_read(i, name) {
            MotionRead::Blind => 0.0,
            MotionRead::Value { s, x } => s * value(x),
            MotionRead::SlopeDifference { s, v, dt, xa, xb } => s * v * (slope(xb) - slope(xa)) / dt,
        }
    }
}

/// A machine-frame direction in the axis frame of axis `axis` (the inverse of the simulator's
/// rotation taking X onto the axis: y → (u_y, −u_x, u_z), z → (u_z, u_y, −u_x)).
pub(crate) fn to_axis_frame(u: [f64; 3], axis: Axis) -> [f64; 3] {
    match axis {
        Axis::X => u,
        Axis::Y => [u[1], -u[0], u[2]],
        Axis::Z => [u[2], u[1], -u[0]],
    }
}

/// The channels of `set` that phase 1 predicts for axis `axis`: every deviation column of every
/// positioning point table of that axis whose sensor is a laser (linear, straightness, vector) or
/// an encoder. Returns the channels and notes on what was skipped.
pub fn channels(set: &MeasurementSet, axis: Axis) -> (Vec<Channel>, Vec<String>) {
    let mut out: Vec<Channel> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    for (run, clock) in set.runs.iter().zip(run_clocks(set, axis)) {
        if run.axis != axis {
            notes.push(format!("run `{}` moves axis {}, the model's axis is {axis}", run.name, run.axis));
            continue;
        }
        let RunData::PointTable { target, run: cyc, direction, t, columns } = &run.data else {
            if let Some((_, note)) = &clock {
                notes.push(note.clone());
            }
            time_series_channels(set, run, clock.as_ref().map(|c| c.0.as_slice()), &mut out, &mut notes);
            continue;
        };
        let t0 = set.run_start(run);
        let times: Vec<f64> = match t {
            Some(t) => t.iter().map(|v| t0 + v).collect(),
            None => vec![t0; target.len()],
        };
        for (name, values) in columns {
            let Some(s) = set.sensor(name) else { continue };
            let ok = matches!(
                s.kind,
                SensorKind::LaserLinear
                    | SensorKind::LaserStraightness
                    | SensorKind::LaserVector
                    | SensorKind::EncoderLinear
                    | SensorKind::EncoderRotary
            );
            if !ok {
                notes.push(format!("run `{}`, sensor `{name}` ({}): not predicted", run.name, s.kind.as_str()));
                continue;
            }
            out.push(Channel {
                run: run.name.clone(),
                sensor: name.clone(),
                kind: s.kind,
                u: to_axis_frame(s.direction, axis),
                r: s.position,
                x: target.clone(),
                d: direction.iter().map(|&v| f64::from(v)).collect(),
                cycle: cyc.clone(),
                t: times.clone(),
                v: vec![0.0; target.len()],
                y: values.clone(),
                sigma: s.sigma.filter(|v| *v > 0.0),
                encoder: None,
            });
        }
    }
    (out, notes)
}

/// The motor-force channels of a constant-velocity or friction-sweep time series (phase 2): every
/// sample at the run's steady velocity v = feed·direction (the procedures sample only the cruise),
/// position from `x_cmd`; its encoder and accelerometer channels. Each sample at its instant in
/// `clock` when given ([`run_clocks`]), else at its stamp. Other time-series channels are listed
/// in `notes` as not predicted.
pub(crate) fn time_series_channels(
    set: &MeasurementSet,
    run: &crate::measurement::Run,
    clock: Option<&[f64]>,
    out: &mut Vec<Channel>,
    notes: &mut Vec<String>,
) {
    let RunData::TimeSeries { t, columns } = &run.data else { return };
    let t = clock.filter(|c| c.len() == t.len()).unwrap_or(t);
    let steady = matches!(run.procedure, Procedure::FrictionSweep | Procedure::ConstantVelocity);
    // A command written to a decimal resolution: read as the smooth profile it rounds, each value
    // with its uncertainty (none for a command written with every digit).
    let (x, x_sigma) = match run.data.command().and_then(|x| smooth_command(t, x, run.feed)) {
        Some((smooth, r)) if r.pieces > 0 => {
            let rms = (r.uncertainty.iter().map(|u| u * u).sum::<f64>() / r.uncertainty.len().max(1) as f64).sqrt();
            let most = r.uncertainty.iter().copied().fold(0.0, f64::max);
            notes.push(format!(
                "run `{}`: its command, written to {} m, is read as the smooth profile those values round ({} \
                 pieces of one polynomial each, degree ≤ {COMMAND_DEGREE}, fitted for least largest error over {} of {} \
                 samples; the largest change {:.3e} m); the profile read is uncertain by {:.3e} m RMS over the run and \
                 {:.3e} m at most, which the σ of its following channel counts",
                run.name,
                fmt_num(r.resolution),
                r.pieces,
                r.smoothed,
                t.len(),
                r.largest_change,
                rms,
                most
            ));
            (smooth, r.uncertainty)
        }
        Some(_) | None => (run.data.command().map(<[f64]>::to_vec).unwrap_or_else(|| vec![0.0; t.len()]), Vec::new()),
    };
    if run.data.command().is_some() {
        out.extend(encoder_channels(set, run, &x, &x_sigma, t, notes));
    }
    for (name, values) in columns {
        if name == COMMAND_COLUMN {
            continue;
        }
        let Some(s) = set.sensor(name) else { continue };
        if matches!(s.kind, SensorKind::EncoderLinear | SensorKind::EncoderRotary) && run.data.command().is_some() {
            continue;
        }
        match (s.kind, run.feed) {
            (SensorKind::Accelerometer, Some(feed)) if run.procedure == Procedure::ConstantVelocity => {
                out.push(steady_channel(
                    set,
                    run,
                    name,
                    s,
                    to_axis_frame(s.direction, run.axis),
                    s.position,
                    &x,
                    t,
                    feed,
                    values,
                ));
            }
            (SensorKind::MotorForce, Some(feed)) if steady => {
                out.push(steady_channel(set, run, name, s, [1.0, 0.0, 0.0], [0.0; 3], &x, t, feed, values));
            }
            // Every other kind (named, so that a new one is decided here), and the two above
            // outside their runs or without a feed.
            (
                SensorKind::Accelerometer
                | SensorKind::MotorForce
                | SensorKind::Command
                | SensorKind::EncoderRotary
                | SensorKind::EncoderLinear
                | SensorKind::LaserLinear
                | SensorKind::LaserStraightness
                | SensorKind::LaserAngular
                | SensorKind::LaserVector
                | SensorKind::Velocity
                | SensorKind::Temperature
                | SensorKind::Pressure
                | SensorKind::Humidity,
                _,
            ) => notes.push(format!(
                "run `{}` ({}), sensor `{name}` ({}): not predicted (time series: only the motor force of \
                 constant-velocity and friction-sweep runs with a `feed`, and encoders against `x_cmd`)",
                run.name,
                run.procedure.as_str(),
                s.kind.as_str()
            )),
        }
    }
}

/// A channel of a constant-feed time-series run: every sample at the run's signed feed, cycle 1, times
/// offset by the run's start (from the set's time origin, [`MeasurementSet::run_start`]); `u`, `r` the sensor's direction and point in the axis frame.
#[allow(clippy::too_many_arguments)]
pub(crate) fn steady_channel(
    set: &MeasurementSet,
    run: &crate::measurement::Run,
    name: &str,
    s: &crate::measurement::Sensor,
    u: [f64; 3],
    r: [f64; 3],
    x: &[f64],
    t: &[f64],
    feed: f64,
    values: &[f64],
) -> Channel {
    let dir = f64::from(run.direction.unwrap_or(1));
    let t0 = set.run_start(run);
    Channel {
        run: run.name.clone(),
        sensor: name.to_string(),
        kind: s.kind,
        u,
        r,
        x: x.to_vec(),
        d: vec![dir; t.len()],
        cycle: vec![1; t.len()],
        t: t.iter().map(|v| t0 + v).collect(),
        v: vec![feed * dir; t.len()],
        y: values.to_vec(),
        sigma: s.sigma.filter(|v| *v > 0.0),
        encoder: None,
    }
}

// ------------------------------------------------------------------------------------------
// The logging clock.

/// The instants each run of `set` is read at when not its stamps, with the note that says why, one
/// entry per run in their order (None: the stamps as written, and every run that is not a time
/// series on axis `axis`).
///
/// A run whose stamps are a regular clock rounded is read at that clock ([`regular_clock`]); one
/// whose command follows the regular clock its jittered stamps scatter about, at that clock
/// ([`ticked_clock`], [`CommandSays::Clock`]). A run whose command cannot tell
/// ([`CommandSays::Undecided`]: it moves too little between rows, or is written to too few digits,
/// to show v·δ) is read at its clock when at least one run of the set says clock, none says
/// stamps, and its stamps scatter alike: an RMS within [`TICKED_ALIKE`] of the median of those
/// that say clock. One host stamps a set's runs; a logger that samples when its software runs
/// says stamps wherever its command can tell.
fn run_clocks(set: &MeasurementSet, axis: Axis) -> Vec<Option<(Vec<f64>, String)>> {
    enum Reading {
        Rounded(RegularClock),
        Ticked(TickedClock),
        Stamps,
    }
    let runs: Vec<(&str, Reading)> = set
        .runs
        .iter()
        .map(|run| {
            let reading = match &run.data {
                RunData::TimeSeries { t, .. } if run.axis == axis => match regular_clock(t) {
                    Some(c) => Reading::Rounded(c),
                    None => {
                        run.data.command().and_then(|x| ticked_clock(t, x)).map_or(Reading::Stamps, Reading::Ticked)
                    }
                },
                RunData::TimeSeries { .. } | RunData::PointTable { .. } => Reading::Stamps,
            };
            (run.name.as_str(), reading)
        })
        .collect();
    let says = |want: CommandSays| -> Vec<(&str, f64)> {
        runs.iter()
            .filter_map(|(name, r)| match r {
                Reading::Ticked(c) if c.says == want => Some((*name, c.rms_shift)),
                Reading::Rounded(_) | Reading::Ticked(_) | Reading::Stamps => None,
            })
            .collect()
    };
    let (on_clock, on_stamps) = (says(CommandSays::Clock), says(CommandSays::Stamps));
    let mut rms: Vec<f64> = on_clock.iter().map(|c| c.1).collect();
    rms.sort_by(f64::total_cmp);
    // index: the median of a non-empty list (None when no run says clock).
    let median = (!rms.is_empty()).then(|| rms[rms.len() / 2]);
    let alike = |r: f64| median.is_some_and(|m| r <= TICKED_ALIKE * m && r * TICKED_ALIKE >= m);
    let ratio = |c: &TickedClock| {
        if c.roughness_ratio.is_finite() {
            format!("{:.1e}", c.roughness_ratio)
        } else {
            "infinitely many".into()
        }
    };
    runs.into_iter()
        .map(|(name, r)| match r {
            Reading::Rounded(c) => Some((
                c.times,
                format!(
                    "run `{name}`: its time stamps, written to {} s, are a regular clock of period {:.9e} s rounded \
                     (the largest stamp is {:.3e} s off it); the model reads the clock's instants",
                    fmt_num(c.resolution),
                    c.period,
                    c.largest_shift
                ),
            )),
            Reading::Ticked(c) => match c.says {
                CommandSays::Clock => Some((
                    c.times.clone(),
                    format!(
                        "run `{name}`: its time stamps scatter about a regular clock of period {:.9e} s (RMS {:.3e} s, \
                         largest {:.3e} s off it), and its command follows the clock's ticks, not the stamps (the \
                         fourth differences are {} times smaller read at the clock); the model reads the \
                         clock's instants",
                        c.period,
                        c.rms_shift,
                        c.largest_shift,
                        ratio(&c)
                    ),
                )),
                CommandSays::Undecided if on_stamps.is_empty() && alike(c.rms_shift) => Some((
                    c.times.clone(),
                    format!(
                        "run `{name}`: its time stamps scatter about a regular clock of period {:.9e} s (RMS {:.3e} s, \
                         largest {:.3e} s off it) as those of run(s) {} whose commands follow their clocks' ticks; its own \
                         command cannot tell (its fourth differences are {} times smaller read at the clock, against \
                         {TICKED_ROUGHNESS} needed), and the model reads the clock's instants",
                        c.period,
                        c.rms_shift,
                        c.largest_shift,
                        on_clock.iter().map(|(n, _)| format!("`{n}`")).collect::<Vec<_>>().join(", "),
                        ratio(&c)
                    ),
                )),
                CommandSays::Undecided | CommandSays::Stamps => None,
            },
            Reading::Stamps => None,
        })
        .collect()
}

/// A run whose command cannot tell follows the set's runs whose commands say clock when its
/// stamps' RMS scatter is within this factor of theirs (their median), either way (the channels'
/// reading of each run's clock):
/// a run of n rows estimates its scatter to about 1/√(2n) (7 % at a hundred rows), and the factor
/// leaves room for a host that is busier in one run than in another.
pub const TICKED_ALIKE: f64 = 3.0;

/// A run's time stamps read as a regular clock rounded to the stamps' resolution
/// ([`regular_clock`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RegularClock {
    /// The clock's period Δ, s.
    pub period: f64,
    /// The stamps' resolution q, s: the coarsest 10⁻ᵏ (k = 0…9) of which every stamp is a whole
    /// multiple ([`STAMP_TOLERANCE`]).
    pub resolution: f64,
    /// The largest |t_i − t̂_i| between a stamp and its instant on the clock, s (≤ q/2).
    pub largest_shift: f64,
    /// The instants t̂_i = t̂₀ + n_i·Δ, s (n_i the tick of sample i: whole, increasing; a step of
    /// more than one is a lost row).
    pub times: Vec<f64>,
}

/// A stamp t is a whole multiple of q when |t/q − round(t/q)| is at most this plus 4ε·|t/q| (the
/// rounding of a decimal read from text and of the division): 10⁻⁹ of q, far below any stamp a
/// file writes (a stamp of 4.001 ms is not a multiple of 1 ms).
pub const STAMP_TOLERANCE: f64 = 1e-9;

/// Stamps already within this fraction of the period from a regular clock are kept as written
/// ([`regular_clock`] returns None): the floating-point rounding of exact instants, not a clock
/// to recover.
pub const CLOCK_EXACT: f64 = 1e-9;

/// Golden-section steps of [`regular_clock`]'s search for the period: each keeps 0.618 of the
/// interval, 120 of them 10⁻²⁵ of it (below a double's resolution of the period).
const CLOCK_SEARCH_STEPS: usize = 120;

/// The regular clock behind a run's time stamps `t` (s, increasing), when the stamps are that clock
/// rounded to their resolution: a controller's trace or a data logger samples on a crystal's
/// ticks, and a file that writes its times to q (0.1 ms, 1 µs) moves each by up to q/2.
///
/// With every stamp a multiple of q (the coarsest 10⁻ᵏ, k = 0…9, to [`STAMP_TOLERANCE`]) and the
/// ticks n_i (n₀ = 0, n_{i+1} = n_i + round((t_{i+1} − t_i)/Δ₀) with Δ₀ the mean interval, then
/// again with Δ₁ = (t_last − t₀)/n_last: a step above one is a lost row), the clock is the line
/// t̂_i = t̂₀ + n_i·Δ of least largest residual (Chebyshev's: Δ by golden section on the
/// residuals' range max − min, convex in Δ; t̂₀ at their mid-range). The stamps are read as
/// that clock when
///
/// ```text
/// max_i |t_i − t̂_i| ≤ q/2·(1 + 10⁻⁶)
/// ```
///
/// (a line through every stamp within half its resolution: exactly what rounding a regular
/// clock leaves) and some residual exceeds [`CLOCK_EXACT`]·Δ. Why: a stamp places its sample
/// only to ±q/2, the clock to a small fraction of q; read as written, a 0.1 ms stamp on a 5.75 ms
/// encoder log at 45 mm/s moves the following error's input by 0.9 % of a slope, a normalised RMS
/// of 59 on a complete model (the tests' encoder generator). Jitter on the instants (a logger that
/// samples when its software runs: the instants are then the stamps) leaves residuals of several
/// σ, which this does not admit once σ ≳ q/4.
///
/// None for fewer than three stamps, stamps that are not increasing or not on a decimal
/// resolution, a clock that changes its rate, jitter beyond the resolution, or stamps already exact.
pub fn regular_clock(t: &[f64]) -> Option<RegularClock> {
    let n = t.len();
    if n < 3 || t.iter().any(|v| !v.is_finite()) || t.windows(2).any(|w| w[1] <= w[0]) {
        return None;
    }
    let resolution = decimal_resolution(t, 9, STAMP_TOLERANCE, 4.0)?;
    // index: n ≥ 3 (checked above).
    let span = t[n - 1] - t[0];
    let ns = clock_ticks(t)?;
    // index: `ns` has n entries.
    let last = ns[n - 1];
    // The residuals' range at period Δ (relative to the first stamp), and their mid-range.
    let range = |period: f64| -> (f64, f64) {
        let (lo, hi) = ns.iter().zip(t).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (k, v)| {
            let r = (v - t[0]) - k * period;
            (lo.min(r), hi.max(r))
        });
        (hi - lo, 0.5 * (hi + lo))
    };
    // A period that leaves every stamp within q/2 lies within 2q/n_last of span/n_last.
    let centre = span / last;
    let (mut a, mut b) = (centre - 2.0 * resolution / last, centre + 2.0 * resolution / last);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (range(c).0, range(d).0);
    for _ in 0..CLOCK_SEARCH_STEPS {
        if fc <= fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = range(c).0;
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = range(d).0;
        }
    }
    let period = 0.5 * (a + b);
    let (width, mid) = range(period);
    let largest_shift = 0.5 * width;
    if !(period > 0.0) || largest_shift > 0.5 * resolution * (1.0 + 1e-6) || largest_shift <= CLOCK_EXACT * period {
        return None;
    }
    let times = ns.iter().map(|k| t[0] + mid + k * period).collect();
    Some(RegularClock { period, resolution, largest_shift, times })
}

/// The tick n_i of each stamp of `t` (s, increasing, at least two) on a clock of about its mean
/// interval: n₀ = 0, n_{i+1} = n_i + round((t_{i+1} − t_i)/Δ₀) with Δ₀ the mean interval, then
/// again with Δ₁ = (t_last − t₀)/n_last (a step above one is a lost row). None when an interval
/// rounds to no tick (a clock that changes its rate).
fn clock_ticks(t: &[f64]) -> Option<Vec<f64>> {
    let n = t.len();
    let (first, last) = (*t.first()?, *t.last()?);
    let ticks = |period: f64| -> Option<Vec<f64>> {
        let mut at = 0.0;
        let mut out = vec![0.0];
        for w in t.windows(2) {
            let step = ((w[1] - w[0]) / period).round();
            if !(step >= 1.0) {
                return None;
            }
            at += step;
            out.push(at);
        }
        Some(out)
    };
    let rough = ticks((last - first) / (n - 1) as f64)?;
    // index: `rough` has n ≥ 1 entries.
    ticks((last - first) / rough[n - 1])
}

/// The regular clock a run's jittered time stamps scatter about, and what its command says of it
/// ([`ticked_clock`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TickedClock {
    /// The clock's period Δ, s (least squares over the stamps).
    pub period: f64,
    /// The RMS of t_i − t̂_i over the stamps, s: the stamps' jitter.
    pub rms_shift: f64,
    /// The largest |t_i − t̂_i|, s (≤ Δ/4).
    pub largest_shift: f64,
    /// The command's roughness read at the stamps over its roughness read at the clock's instants
    /// (its fourth divided differences by their median or mean, [`command_roughness`]: the one
    /// further from one).
    pub roughness_ratio: f64,
    /// What the ratio says ([`TICKED_ROUGHNESS`]).
    pub says: CommandSays,
    /// The instants t̂_i = t̂₀ + n_i·Δ, s (n_i the tick of sample i: whole, increasing; a step of
    /// more than one is a lost row).
    pub times: Vec<f64>,
}

/// What a run's command says of the regular clock its stamps scatter about ([`ticked_clock`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandSays {
    /// Read at the stamps it is at least [`TICKED_ROUGHNESS`] times rougher (by the median or the
    /// mean of [`Roughness`], and not the other way round by either): the readings are on the
    /// clock's ticks.
    Clock,
    /// Read at the clock's instants it is at least [`TICKED_ROUGHNESS`] times rougher (by either,
    /// and not the other way round by either): the readings are at the stamps.
    Stamps,
    /// Neither, or both: the command moves too little between rows, or is written to too few
    /// digits, to show the jitter.
    Undecided,
}

/// The command read at the stamps must be at least this many times rougher than read at the
/// clock's instants to say clock, or this many times smoother to say stamps ([`CommandSays`]): on
/// a controller's trace stamped with jitter the ratio is v·σ_t over the command's rounding (10³
/// and more), on a logger that samples at its stamps it is below one, and a command written too
/// coarsely to show the jitter gives about one.
pub const TICKED_ROUGHNESS: f64 = 10.0;

/// Stamps off their clock by more than this fraction of its period are not one clock's ticks
/// ([`ticked_clock`]): each stamp must lie nearer its own tick than any other's.
pub const TICKED_LARGEST_SHIFT: f64 = 0.25;

/// The order of the divided differences [`command_roughness`] takes: a smooth motion's part,
/// x⁽⁴⁾·Δ⁴/24, falls with the order as (ωΔ)ᵏ, while instants off by δ add about v·δ·√70 to a
/// fourth difference. At the third order a slow reversal of the tests' encoder generator (3 mm,
/// 1 s, 4 ms rows) leaves 6 nm, as much as 1 µs of jitter adds to its command.
pub const COMMAND_DIFFERENCE_ORDER: usize = 4;

/// How rough a command is read at given instants ([`command_roughness`]), m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roughness {
    /// The median of the windows' |x[τ_i, …, τ_{i+k}]|·Δᵏ: what most of the run shows.
    pub median: f64,
    /// Their mean: what a few windows show. Stamps of a jittered clock written to a resolution
    /// coarser than the jitter are mostly exact, and only a few (1 % at 10 µs on 1.9 µs of jitter)
    /// are a whole resolution off; the median does not see them, and read at them a complete
    /// model of the tests' encoder generator gave normalised RMS 12.7 (draw 2005).
    pub mean: f64,
}

/// |x[τ_i, …, τ_{i+k}]|·Δᵏ (m), the divided difference of order k = [`COMMAND_DIFFERENCE_ORDER`]
/// of the command x (m) read at the instants τ (s, one per value), Δ the clock's period (s), over
/// the windows of k + 1 samples in which the command moves, by its median and mean over the run:
/// on a smooth motion it is x⁽ᵏ⁾·Δᵏ/k!, and instants off the command's own by δ add about v·δ.
/// None with fewer than four such windows or instants of another length.
pub fn command_roughness(x: &[f64], tau: &[f64], period: f64) -> Option<Roughness> {
    let k = COMMAND_DIFFERENCE_ORDER;
    if tau.len() != x.len() {
        return None;
    }
    let mut diffs: Vec<f64> = x
        .windows(k + 1)
        .zip(tau.windows(k + 1))
        .filter(|(xw, _)| xw.windows(2).any(|w| w[1] != w[0]))
        .map(|(xw, tw)| {
            // Newton's table in place: after pass j, d[i] = x[τ_i, …, τ_{i+j}].
            let mut d = [0.0; COMMAND_DIFFERENCE_ORDER + 1];
            d.copy_from_slice(xw);
            for j in 1..=k {
                for i in 0..=k - j {
                    // index: i + j ≤ k, both windows hold k + 1 values.
                    d[i] = (d[i + 1] - d[i]) / (tw[i + j] - tw[i]);
                }
            }
            (d[0] * period.powi(k as i32)).abs()
        })
        .collect();
    if diffs.len() < 4 {
        return None;
    }
    let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
    let mid = diffs.len() / 2;
    let (_, median, _) = diffs.select_nth_unstable_by(mid, f64::total_cmp);
    Some(Roughness { median: *median, mean })
}

/// The regular clock behind a run's jittered time stamps `t` (s, increasing), and what its command
/// `x` (m, one value per stamp) says of it: whether the readings were taken on that clock's ticks
/// (a controller logs on its servo ticks, and a host that stamps the rows as they arrive adds its
/// own jitter) or at the stamps.
///
/// The ticks n_i as in [`regular_clock`], the clock the least-squares line t̂_i = t̂₀ + n_i·Δ. It is
/// a clock when every stamp lies within [`TICKED_LARGEST_SHIFT`]·Δ of it and some beyond
/// [`CLOCK_EXACT`]·Δ; the command says [`CommandSays::Clock`] when it is [`TICKED_ROUGHNESS`] times
/// smoother read at the clock's instants than at the stamps by the median or the mean of its
/// fourth differences ([`command_roughness`]) and not the other way round by either,
/// [`CommandSays::Stamps`] when the other way round. Why the command decides: it is a smooth
/// function of the controller's time (linear in a cruise), so read at instants off its own by δ
/// it gains a roughness of about v·δ; the stamps alone cannot tell a jittered stamp on a regular
/// reading from a logger that really samples when its software runs (whose command then follows
/// the stamps). Read at the stamps, 1–20 µs of jitter moves the following error's input by
/// v·δ, tens of nanometres, and a complete model of the tests' encoder generator reached
/// normalised RMS 1.8–39.
///
/// None for fewer than eight stamps, stamps that are not increasing, a command of another length
/// or not finite, a clock that changes its rate, stamps already exact, or a command that stands.
pub fn ticked_clock(t: &[f64], x: &[f64]) -> Option<TickedClock> {
    let n = t.len();
    if n < 8 || x.len() != n || t.iter().chain(x).any(|v| !v.is_finite()) || t.windows(2).any(|w| w[1] <= w[0]) {
        return None;
    }
    let ns = clock_ticks(t)?;
    // The least-squares line through (n_i, t_i), about the means.
    let (nm, tm) = (ns.iter().sum::<f64>() / n as f64, t.iter().sum::<f64>() / n as f64);
    let snn: f64 = ns.iter().map(|k| (k - nm).powi(2)).sum();
    let snt: f64 = ns.iter().zip(t).map(|(k, v)| (k - nm) * (v - tm)).sum();
    let period = snt / snn;
    let times: Vec<f64> = ns.iter().map(|k| tm + (k - nm) * period).collect();
    let shifts: Vec<f64> = t.iter().zip(&times).map(|(a, b)| a - b).collect();
    let largest_shift = shifts.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    if !(period > 0.0) || largest_shift > TICKED_LARGEST_SHIFT * period || largest_shift <= CLOCK_EXACT * period {
        return None;
    }
    let (at_stamps, at_clock) = (command_roughness(x, t, period)?, command_roughness(x, &times, period)?);
    // Stamps over clock, by the median and by the mean (0/0: 1).
    let ratio = |a: f64, b: f64| match (a > 0.0, b > 0.0) {
        (_, true) => a / b,
        (true, false) => f64::INFINITY,
        (false, false) => 1.0,
    };
    let ratios = [ratio(at_stamps.median, at_clock.median), ratio(at_stamps.mean, at_clock.mean)];
    let clock = ratios.iter().any(|r| *r >= TICKED_ROUGHNESS);
    let stamps = ratios.iter().any(|r| *r * TICKED_ROUGHNESS <= 1.0);
    let says = match (clock, stamps) {
        (true, false) => CommandSays::Clock,
        (false, true) => CommandSays::Stamps,
        (true, true) | (false, false) => CommandSays::Undecided,
    };
    let rms_shift = (shifts.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
    // The ratio further from one (the one that decides).
    let roughness_ratio = if ratios[0].ln().abs() >= ratios[1].ln().abs() { ratios[0] } else { ratios[1] };
    Some(TickedClock { period, rms_shift, largest_shift, roughness_ratio, says, times })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A regular clock of period `period` from `start` (s) over `n` ticks, each row after the first
    /// lost with probability `lost`, each instant moved by Gaussian jitter of σ `jitter`: the true
    /// instants and their stamps rounded to `q`.
    fn stamped(
        rng: &mut ChaCha8Rng,
        period: f64,
        start: f64,
        n: usize,
        lost: f64,
        jitter: f64,
        q: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let normal = rand_distr::Normal::new(0.0, 1.0).unwrap();
        let mut truth = Vec::new();
        for k in 0..n {
            if k > 0 && rng.gen::<f64>() < lost {
                continue;
            }
            truth.push(start + k as f64 * period + jitter * rng.sample(normal));
        }
        let stamps = truth.iter().map(|t| (t / q).round() * q).collect();
        (truth, stamps)
    }

    /// Clocks a logger or a controller keeps (periods off any decimal grid: 1.25 ms of a 4 kHz
    /// servo every 5 ticks, 0.390625 ms of a 2560 Hz logger, 1/3 ms, 5.75 ms, 12.3457 ms; random
    /// starts; 2 % of rows lost), their stamps rounded to the coarsest decimal at most a quarter of
    /// the period: the clock is found, its period within 10⁻⁶, the resolution is the stamps', and
    /// every recovered instant is within q/(2m) + q/50 of the true one, where the stamps are up to
    /// q/2 off. m: the least whole number (≤ 1000) with m·Δ/q whole. A clock commensurate with
    /// the resolution repeats m rounding errors, which leave the clock's phase undetermined within
    /// q/m (Δ = 1.25 ms on 0.1 ms stamps, m = 2: errors 0 and ±q/2, and when every half-way stamp
    /// rounds the same way, a phase anywhere in q/2 fits); otherwise the errors fill the interval
    /// and the phase is fixed to a small part of q.
    #[test]
    fn a_rounded_regular_clock_is_recovered() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for (d, &period) in [1.25e-3, 0.390625e-3, 1.0 / 3000.0, 5.75e-3, 0.0123457].iter().enumerate() {
            let q = [1e-3, 1e-4, 1e-5, 1e-6].into_iter().find(|q| *q <= period / 4.0).unwrap();
            let start = (rng.gen::<f64>() * 100.0 / q).round() * q;
            let (truth, stamps) = stamped(&mut rng, period, start, 3000, 0.02, 0.0, q);
            let c = regular_clock(&stamps).unwrap_or_else(|| panic!("clock {d} ({period} s) not found"));
            assert_eq!(c.resolution, q, "clock {d}");
            let m = (1..=1000).find(|m| {
                let u = *m as f64 * period / q;
                (u - u.round()).abs() <= 1e-9 * u
            });
            let bound = q / (2.0 * m.map_or(f64::INFINITY, |m| m as f64)) + q / 50.0;
            let worst = c.times.iter().zip(&truth).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst <= bound, "clock {d}: recovered instants off by {worst:e} s (q = {q:e} s, m = {m:?})");
            assert!((c.period / period - 1.0).abs() <= 1e-6, "clock {d}: period {} s", c.period);
            assert!(c.largest_shift <= q / 2.0 * (1.0 + 1e-6), "clock {d}");
        }
    }

    /// What is not a rounded regular clock keeps its stamps: jitter of σ = q/2 on the instants
    /// (the instants are then the stamps), a rate that changes within the run, exact stamps (to
    /// floating point), stamps on no decimal resolution, and two stamps.
    #[test]
    fn other_stamps_are_kept() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (_, jittered) = stamped(&mut rng, 0.4e-3, 0.0, 3000, 0.0, 0.5e-6, 1e-6);
        assert!(regular_clock(&jittered).is_none(), "jitter of q/2 read as rounding");
        let (_, slow) = stamped(&mut rng, 1.25e-3, 0.0, 1500, 0.0, 0.0, 1e-4);
        let (_, fast) = stamped(&mut rng, 1.0e-3, 1500.0 * 1.25e-3, 1500, 0.0, 0.0, 1e-4);
        let switched: Vec<f64> = slow.into_iter().chain(fast).collect();
        assert!(regular_clock(&switched).is_none(), "a rate change read as one clock");
        let exact: Vec<f64> = (0..3000).map(|k| 17.0 + k as f64 * 0.25e-3).collect();
        assert!(regular_clock(&exact).is_none(), "exact stamps moved");
        let arbitrary: Vec<f64> = (0..3000).map(|k| k as f64 * 0.25e-3 + 1e-3 * rng.gen::<f64>() * 1e-3).collect();
        assert!(regular_clock(&arbitrary).is_none(), "stamps on no decimal resolution");
        assert!(regular_clock(&[0.0, 1.2e-3]).is_none());
    }

    /// A controller's ticks of period `period` from `start` (s) over `n` ticks, each row after the
    /// first lost with probability `lost`, and their stamps: each tick moved by Gaussian jitter of
    /// σ `jitter` (a host's clock; the readings stay at the ticks).
    fn ticked(rng: &mut ChaCha8Rng, period: f64, start: f64, n: usize, lost: f64, jitter: f64) -> (Vec<f64>, Vec<f64>) {
        let normal = rand_distr::Normal::new(0.0, 1.0).unwrap();
        let ticks: Vec<f64> =
            (0..n).filter(|k| *k == 0 || rng.gen::<f64>() >= lost).map(|k| start + k as f64 * period).collect();
        let stamps = ticks.iter().map(|t| t + jitter * rng.sample(normal)).collect();
        (ticks, stamps)
    }

    /// A command on a controller's ticks: a cruise at v (m/s) plus a wave of amplitude `a` (m) and
    /// angular frequency `w` (rad/s), at each of `instants` (s).
    fn command(rng: &mut ChaCha8Rng, v: f64, a: f64, w: f64, instants: &[f64]) -> Vec<f64> {
        let (x0, phase) = (rng.gen_range(-0.2..0.6), rng.gen_range(0.0..6.3));
        instants.iter().map(|t| x0 + v * t + a * (w * t + phase).sin()).collect()
    }

    /// Log-uniform between `lo` and `hi`.
    fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
        (lo.ln() + rng.gen::<f64>() * (hi.ln() - lo.ln())).exp()
    }

    /// Controller traces whose stamps a host wrote with jitter (σ log-uniform from 0.3 µs to 1/40 of
    /// the period, periods off any decimal grid, cruise speeds 5 mm/min to 0.5 m/s, a wave of
    /// 1 µm–1 mm and 0.5–4 s on the cruise, 2 % of rows lost): 300 draws. The command shows the
    /// jitter when its part of a fourth difference, about v·σ·√70/24 (v the slowest speed of the
    /// run), is 100 times the motion's own, a·ω⁴·Δ⁴/24, and its floating-point rounding (10⁻¹⁵ m).
    /// In every such draw (at least 200 of the 300 qualify) the stamps are read at the clock, the
    /// period within 4 × the least-squares slope's σ·√(12/N³) (N ticks), and every recovered
    /// instant within 9σ/√n of the true one (the least-squares line's error at the ends of the run
    /// has σ·√(4/n): 4.5 × that, exceeded once in 10⁵ ends). And stamps of 2 µs jitter written to
    /// 10 µs (most exact, a few a whole 10 µs off) say clock.
    #[test]
    fn jittered_stamps_of_a_ticked_command_are_read_at_the_clock() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut qualified = 0;
        for d in 0..300 {
            let period: f64 =
                [1e-3, 1.25e-3, 0.390625e-3, 1.0 / 3000.0, 5.75e-3, 8.25e-3][d % 6] * rng.gen_range(0.999..1.001);
            let sigma = log_uniform(&mut rng, 0.3e-6, period / 40.0);
            let n = rng.gen_range(200..3000);
            let start = rng.gen_range(0.0..10.0);
            let (truth, stamps) = ticked(&mut rng, period, start, n, 0.02, sigma);
            let v = log_uniform(&mut rng, 5.0 / 60e3, 0.5);
            let (a, w) = (log_uniform(&mut rng, 1e-6, 1e-3), std::f64::consts::TAU / rng.gen_range(0.5..4.0));
            let x = command(&mut rng, v, a, w, &truth);
            let jitter_part = (v - a * w).max(0.0) * sigma * 70f64.sqrt() / 24.0;
            if jitter_part < 100.0 * (a * (w * period).powi(4) / 24.0 + 1e-15) {
                continue;
            }
            qualified += 1;
            let c =
                ticked_clock(&stamps, &x).unwrap_or_else(|| panic!("draw {d} (σ {sigma:e} s) not read at its clock"));
            let tol = 4.0 * sigma * (12.0 / (n as f64).powi(3)).sqrt();
            assert!((c.period - period).abs() <= tol, "draw {d}: period {} s against {period} s", c.period);
            let worst = c.times.iter().zip(&truth).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            let bound = 9.0 * sigma / (truth.len() as f64).sqrt();
            assert!(worst <= bound, "draw {d}: instants off by {worst:e} s (σ {sigma:e} s, bound {bound:e} s)");
            assert!(c.roughness_ratio >= TICKED_ROUGHNESS && c.largest_shift <= TICKED_LARGEST_SHIFT * period);
        }
        assert!(qualified >= 200, "{qualified} of 300 draws show their jitter in the command");
        // Stamps written to a resolution coarser than the jitter (2 µs on 1.25 ms, written to
        // 10 µs): most exact, a few a whole 10 µs off; the mean of the roughness sees them.
        let (truth, stamps) = ticked(&mut rng, 1.25e-3, 0.0, 3000, 0.0, 2e-6);
        let stamps: Vec<f64> = stamps.iter().map(|t| (t / 1e-5).round() * 1e-5).collect();
        let x = command(&mut rng, 0.05, 0.0, 1.0, &truth);
        let c = ticked_clock(&stamps, &x).map(|c| c.says);
        assert_eq!(c, Some(CommandSays::Clock), "stamps of a jittered clock written to 10 µs");
    }

    /// What the command does not place on a regular clock: a logger that samples at its jittered
    /// stamps (the command read at the stamps) says stamps in each of 50 draws; a command written
    /// to 1 µm where the jitter moves it by v·σ = 25 nm (rounding errors that do not repeat) cannot
    /// tell; a command that stands, exact stamps, a rate that changes within the run, and a
    /// command of another length give no clock.
    #[test]
    fn stamps_a_command_follows_are_kept() {
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        for d in 0..50 {
            let (_, stamps) = stamped(&mut rng, 0.4e-3, 1.0, 2000, 0.02, 2e-6, 1e-9);
            let at_stamps = command(&mut rng, 0.05, 1e-4, 3.0, &stamps);
            let says = ticked_clock(&stamps, &at_stamps).map(|c| c.says);
            assert_eq!(says, Some(CommandSays::Stamps), "draw {d}: a logger's own instants");
        }
        let (truth, stamps) = ticked(&mut rng, 1e-3, 0.0, 3000, 0.0, 0.5e-6);
        // 0.0503 m/s: 50.3 µm a tick, so the rounding to 1 µm does not repeat.
        let coarse: Vec<f64> =
            command(&mut rng, 0.0503, 0.0, 1.0, &truth).iter().map(|x| (x * 1e6).round() / 1e6).collect();
        let says = ticked_clock(&stamps, &coarse).map(|c| c.says);
        assert_eq!(says, Some(CommandSays::Undecided), "a command written to 1 µm");
        assert!(ticked_clock(&stamps, &vec![0.25; stamps.len()]).is_none(), "a standing command decided the clock");
        let exact: Vec<f64> = (0..3000).map(|k| 17.0 + k as f64 * 0.25e-3).collect();
        assert!(ticked_clock(&exact, &command(&mut rng, 0.1, 0.0, 1.0, &exact)).is_none(), "exact stamps moved");
        let (slow_t, slow) = ticked(&mut rng, 1.25e-3, 0.0, 1500, 0.0, 1e-6);
        let (fast_t, fast) = ticked(&mut rng, 1.0e-3, 1500.0 * 1.25e-3, 1500, 0.0, 1e-6);
        let (switched, truth): (Vec<f64>, Vec<f64>) =
            slow.into_iter().chain(fast).zip(slow_t.into_iter().chain(fast_t)).unzip();
        assert!(
            ticked_clock(&switched, &command(&mut rng, 0.1, 0.0, 1.0, &truth)).is_none(),
            "a rate change read as one clock"
        );
        assert!(ticked_clock(&stamps[..100], &coarse[..99]).is_none());
    }
}
