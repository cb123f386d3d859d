//! Channels: the measurement set as stacked channels with per-sample sensitivities.

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
        if self.is_laser() || self.encoder.is_some() {
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
    for run in &set.runs {
        if run.axis != axis {
            notes.push(format!("run `{}` moves axis {}, the model's axis is {axis}", run.name, run.axis));
            continue;
        }
        let RunData::PointTable { target, run: cyc, direction, t, columns } = &run.data else {
            time_series_channels(set, run, &mut out, &mut notes);
            continue;
        };
        let t0 = run.start_time.unwrap_or(0.0);
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
/// position from `x_cmd`. Other time-series channels are listed in `notes` as not predicted.
pub(crate) fn time_series_channels(
    set: &MeasurementSet,
    run: &crate::measurement::Run,
    out: &mut Vec<Channel>,
    notes: &mut Vec<String>,
) {
    let RunData::TimeSeries { t, columns } = &run.data else { return };
    let steady = matches!(run.procedure, Procedure::FrictionSweep | Procedure::ConstantVelocity);
    let x: Vec<f64> = run.data.command().map(<[f64]>::to_vec).unwrap_or_else(|| vec![0.0; t.len()]);
    if run.data.command().is_some() {
        out.extend(encoder_channels(set, run, &x, t, notes));
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
                out.push(steady_channel(run, name, s, [1.0, 0.0, 0.0], [0.0; 3], &x, t, feed, values));
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
/// offset by the run's start time; `u`, `r` the sensor's direction and point in the axis frame.
#[allow(clippy::too_many_arguments)]
pub(crate) fn steady_channel(
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
    let t0 = run.start_time.unwrap_or(0.0);
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
