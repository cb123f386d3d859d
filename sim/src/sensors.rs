//! Sensors (DESIGN.md §5): each reads the noise-free truth trace of a run and adds its own errors and
//! seeded noise. Sensor noise never feeds back into the physics, so one simulated trace serves many
//! noise draws (tolerance studies).
//!
//! Mounting: `position` is a point of the moving body in the axis frame (m, from the axis reference
//! point); `direction` is the sensitive direction: in the machine frame for lasers (the optics sit on
//! the bed), in the axis frame of the moving body for accelerometers (they tilt with it).

use crate::air::{edlen_index, Air, HENE_WAVELENGTH_UM};
use crate::axis_sim::{Sample, StructuralMode, GRAVITY};
use crate::machine::AxisModel;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rapier3d_f64::glamx::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Why a sensor cannot be read on an axis: its mounting does not fit the machine, or a run names a
/// sensor the scenario does not declare.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SensorError {
    /// `link` names no link of the moving body.
    #[error("sensor `{sensor}`: link `{link}` is not a link of the moving body")]
    UnknownLink {
        /// The sensor's name.
        sensor: String,
        /// The link it names.
        link: String,
    },
    /// Both `position` and `link` are given.
    #[error("sensor `{0}`: give either position or link, not both")]
    PositionAndLink(String),
    /// A run names a sensor that is not declared.
    #[error("run `{run}` names sensor `{sensor}`, which is not declared")]
    Undeclared {
        /// The run's name.
        run: String,
        /// The sensor it names.
        sensor: String,
    },
}

/// Sensor kinds, named as in FORMAT.md §1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// Commanded position of the axis, m (the interpolator's output, no noise).
    Command,
    /// Motor encoder: position the servo sees through screw and motor in a semi-closed loop, m.
    EncoderRotary,
    /// Linear scale on the axis: position read by the scale with its own errors, m.
    EncoderLinear,
    /// Laser interferometer, linear: displacement of the mount point along `direction` from its home position, m.
    LaserLinear,
    /// Laser straightness optics: displacement of the mount point across the motion (along `direction`), m.
    LaserStraightness,
    /// Laser angular optics: rotation of the body about `direction` (pitch, yaw or roll), rad.
    LaserAngular,
    /// Laser vector (diagonal) measurement: displacement of the mount point along a slanted `direction`, m.
    LaserVector,
    /// Accelerometer on the body: specific force along `direction` (includes gravity when tilted), m/s².
    Accelerometer,
    /// Drive force commanded by the servo, N.
    MotorForce,
    /// Velocity of the body along the axis, m/s.
    Velocity,
    /// Air or machine temperature, K.
    Temperature,
    /// Air pressure, Pa (vmt addition, for the laser's Edlén correction).
    Pressure,
    /// Relative humidity, ratio (vmt addition; `percent` unit allowed).
    Humidity,
}

impl SensorKind {
    /// Every kind.
    pub const ALL: [SensorKind; 13] = [
        SensorKind::Command,
        SensorKind::EncoderRotary,
        SensorKind::EncoderLinear,
        SensorKind::LaserLinear,
        SensorKind::LaserStraightness,
        SensorKind::LaserAngular,
        SensorKind::LaserVector,
        SensorKind::Accelerometer,
        SensorKind::MotorForce,
        SensorKind::Velocity,
        SensorKind::Temperature,
        SensorKind::Pressure,
        SensorKind::Humidity,
    ];

    /// Parses a manifest `kind` string.
    pub fn parse(s: &str) -> Option<SensorKind> {
        SensorKind::ALL.iter().copied().find(|k| k.as_str() == s)
    }

    /// The name as written in manifests, e.g. `laser_linear`.
    pub fn as_str(&self) -> &'static str {
        match self {
            SensorKind::Command => "command",
            SensorKind::EncoderRotary => "encoder_rotary",
            SensorKind::EncoderLinear => "encoder_linear",
            SensorKind::LaserLinear => "laser_linear",
            SensorKind::LaserStraightness => "laser_straightness",
            SensorKind::LaserAngular => "laser_angular",
            SensorKind::LaserVector => "laser_vector",
            SensorKind::Accelerometer => "accelerometer",
            SensorKind::MotorForce => "motor_force",
            SensorKind::Velocity => "velocity",
            SensorKind::Temperature => "temperature",
            SensorKind::Pressure => "pressure",
            SensorKind::Humidity => "humidity",
        }
    }

    /// The laser interferometer kinds (linear, straightness, angular, vector): one predicate for every
    /// "is a laser" question (air and material scale errors, gains, laser-line identification).
    pub fn is_laser(self) -> bool {
        match self {
            SensorKind::LaserLinear
            | SensorKind::LaserStraightness
            | SensorKind::LaserAngular
            | SensorKind::LaserVector => true,
            SensorKind::Command
            | SensorKind::EncoderRotary
            | SensorKind::EncoderLinear
            | SensorKind::Accelerometer
            | SensorKind::MotorForce
            | SensorKind::Velocity
            | SensorKind::Temperature
            | SensorKind::Pressure
            | SensorKind::Humidity => false,
        }
    }

    /// A laser that reads the displacement of a point along its beam, m (linear, straightness, vector;
    /// not the angular laser): the readings the laser-line identifiers use.
    pub fn is_laser_line(self) -> bool {
        self.is_laser() && self != SensorKind::LaserAngular
    }

    /// In a positioning point table the sensor holds a deviation (actual − target) rather than a reading.
    pub fn reads_deviation(&self) -> bool {
        matches!(
            self,
            SensorKind::EncoderLinear | SensorKind::EncoderRotary | SensorKind::LaserLinear | SensorKind::LaserVector
        )
    }
}

/// Accelerometer presets (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AccelPreset {
    /// MEMS part: 25 µg/√Hz, 2 mg bias, 0.5 % scale error, 16-bit over ±2 g (61 µg LSB), DC response.
    Mems,
    /// Seismic piezo part: 0.3 µg/√Hz, no DC response (first-order high-pass at 0.2 Hz), 24-bit ADC.
    Piezo,
}

/// A sensor as a scenario declares it. Unset error terms are zero.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Sensor name, the column name in the measurement set.
    pub name: String,
    /// What the sensor measures (FORMAT.md §1).
    pub kind: SensorKind,
    /// Mount point on the moving body, axis frame, m. Alternatively `link`.
    #[serde(default)]
    pub position: Option<[f64; 3]>,
    /// A link of the moving body whose origin is the mount point.
    #[serde(default)]
    pub link: Option<String>,
    /// Sensitive direction (unit vector after normalisation).
    #[serde(default = "default_direction")]
    pub direction: [f64; 3],
    /// White noise, 1σ per sample, SI unit of the channel.
    #[serde(default)]
    pub sigma: f64,
    /// Quantisation step (resolution, LSB), SI unit of the channel.
    #[serde(default)]
    pub resolution: f64,
    /// Accelerometer noise density, m/s²/√Hz (one-sided): σ per sample = ρ·√(fs/2).
    #[serde(default)]
    pub noise_density: f64,
    /// Constant bias, SI unit of the channel.
    #[serde(default)]
    pub bias: f64,
    /// Scale-factor error (reading = (1 + s)·true).
    #[serde(default)]
    pub scale_factor: f64,
    /// First-order high-pass corner, Hz (piezo accelerometers have no DC response); 0 = DC coupled.
    #[serde(default)]
    pub highpass: f64,
    /// Accelerometer preset (DESIGN.md §5): fills the noise density, bias, scale-factor, resolution and
    /// high-pass terms the spec leaves zero ([`SensorSpec::resolved`]).
    #[serde(default)]
    pub preset: Option<AccelPreset>,
    /// Accelerometer bias random walk, m/s² per √s (bias drift).
    #[serde(default)]
    pub bias_drift: f64,
    /// Mounting misalignment of the sensitive axis, rotation vector in the body frame, rad: a tilted
    /// accelerometer sees gravity, g·sin(angle).
    #[serde(default)]
    pub tilt: [f64; 3],
    /// Lasers: the air the beam actually runs through (default 20 °C, 101 325 Pa, 50 %).
    #[serde(default)]
    pub air: Option<Air>,
    /// Lasers: the air the laser's compensation assumes (default: the actual air, no error).
    #[serde(default)]
    pub assumed_air: Option<Air>,
    /// Linear lasers: the true temperature of the measured machine/workpiece, °C (default 20 °C, the
    /// ISO 1 reference temperature).
    #[serde(default = "default_material_temperature")]
    pub material_temperature: f64,
    /// Linear lasers: the expansion coefficient the laser normalises with, 1/K (default 11.5e-6, steel).
    #[serde(default = "default_material_alpha")]
    pub material_alpha: f64,
    /// Linear lasers: the material temperature the laser's material sensor reports and the normalisation
    /// to 20 °C uses, °C (default: the true material temperature, no error).
    #[serde(default)]
    pub assumed_material_temperature: Option<f64>,
}

fn default_direction() -> [f64; 3] {
    [1.0, 0.0, 0.0]
}

/// ISO 1 reference temperature of dimensional metrology, °C.
pub const REFERENCE_TEMPERATURE: f64 = 20.0;

/// Expansion coefficient of steel used as the default material of a laser's normalisation, 1/K.
pub const STEEL_ALPHA: f64 = 11.5e-6;

fn default_material_temperature() -> f64 {
    REFERENCE_TEMPERATURE
}

fn default_material_alpha() -> f64 {
    STEEL_ALPHA
}

impl SensorSpec {
    /// A sensor of the given kind with no errors, mounted at the body frame origin, sensing along x.
    pub fn new(name: &str, kind: SensorKind) -> SensorSpec {
        SensorSpec {
            name: name.to_string(),
            kind,
            position: None,
            link: None,
            direction: default_direction(),
            sigma: 0.0,
            resolution: 0.0,
            noise_density: 0.0,
            bias: 0.0,
            scale_factor: 0.0,
            highpass: 0.0,
            preset: None,
            bias_drift: 0.0,
            tilt: [0.0; 3],
            air: None,
            assumed_air: None,
            material_temperature: REFERENCE_TEMPERATURE,
            material_alpha: STEEL_ALPHA,
            assumed_material_temperature: None,
        }
    }

    /// The spec with its preset's values filled in where the spec leaves them zero.
    pub fn resolved(&self) -> SensorSpec {
        let mut s = self.clone();
        let ug = GRAVITY * 1e-6;
        let (rho, bias, scale, lsb, hp) = match self.preset {
            Some(AccelPreset::Mems) => (25.0 * ug, 2000.0 * ug, 0.005, 4.0 * GRAVITY / 65536.0, 0.0),
            Some(AccelPreset::Piezo) => (0.3 * ug, 0.0, 0.0, 20.0 * GRAVITY / 16_777_216.0, 0.2),
            None => return s,
        };
        let fill = |v: &mut f64, d: f64| {
            if *v == 0.0 {
                *v = d
            }
        };
        fill(&mut s.noise_density, rho);
        fill(&mut s.bias, bias);
        fill(&mut s.scale_factor, scale);
        fill(&mut s.resolution, lsb);
        fill(&mut s.highpass, hp);
        s
    }

    /// Mount point in the body frame.
    pub fn mount(&self, model: &AxisModel) -> Result<DVec3, SensorError> {
        match (&self.position, &self.link) {
            (Some(p), None) => Ok(model.home.rotation.inverse() * (model.axis_rotation * DVec3::from_array(*p))),
            (None, Some(l)) => model
                .link(l)
                .map(|f| f.translation)
                .ok_or_else(|| SensorError::UnknownLink { sensor: self.name.clone(), link: l.clone() }),
            (None, None) => Ok(DVec3::ZERO),
            (Some(_), Some(_)) => Err(SensorError::PositionAndLink(self.name.clone())),
        }
    }

    /// Mount point in the axis frame (as written in a measurement-set manifest).
    pub fn axis_position(&self, model: &AxisModel) -> Result<[f64; 3], SensorError> {
        Ok(model.body_to_axis(self.mount(model)?).to_array())
    }

    /// Unit vector of the sensitive direction (`direction` normalised; zero for a zero vector).
    pub fn unit_direction(&self) -> DVec3 {
        DVec3::from_array(self.direction).normalize_or_zero()
    }

    /// Relative scale error of a laser from the air: n_actual/n_assumed − 1 (Edlén).
    pub fn air_scale_error(&self) -> f64 {
        let actual = self.air.unwrap_or(Air::REFERENCE);
        let assumed = self.assumed_air.unwrap_or(actual);
        edlen_index(&actual, HENE_WAVELENGTH_UM) / edlen_index(&assumed, HENE_WAVELENGTH_UM) - 1.0
    }

    /// Relative scale error of a length-measuring laser (`laser_linear`, `laser_vector`) from its material
    /// normalisation to 20 °C (ISO 1; DESIGN.md §4/§5). A part whose 20 °C length is L is, at the true
    /// temperature T, L·(1 + α·(T − 20)) long; the laser divides what it measures by 1 + α·(T_a − 20) with
    /// the assumed (sensed) temperature T_a, so it reads L·(1 + α·(T − 20))/(1 + α·(T_a − 20)):
    /// a relative error
    ///   e = α·(T − T_a)/(1 + α·(T_a − 20)) = α·(T − T_a)·(1 − α·(T_a − 20) + …),
    /// to first order α·(T − T_a). Zero for the other kinds, whose readings are not normalised.
    pub fn material_scale_error(&self) -> f64 {
        if !matches!(self.kind, SensorKind::LaserLinear | SensorKind::LaserVector) {
            return 0.0;
        }
        let t = self.material_temperature;
        let ta = self.assumed_material_temperature.unwrap_or(t);
        self.material_alpha * (t - ta) / (1.0 + self.material_alpha * (ta - REFERENCE_TEMPERATURE))
    }

    /// Overall gain of the sensor on the true reading, 1 + s: for lasers the product of the independent
    /// factors (1 + s)·(1 + e_air)·(1 + e_material), first order 1 + s + e_air + e_material.
    pub fn gain(&self) -> f64 {
        if self.is_laser() {
            (1.0 + self.scale_factor) * (1.0 + self.air_scale_error()) * (1.0 + self.material_scale_error())
        } else {
            1.0 + self.scale_factor
        }
    }

    fn is_laser(&self) -> bool {
        self.kind.is_laser()
    }
}

/// Noise-free reading of a sensor at every sample of a trace (index 0 is the sample before the first
/// output for accelerometers, which average over the preceding interval). Laser and encoder readings are
/// displacements from the axis home position, m; accelerometers proper acceleration, m/s².
pub fn true_readings(
    spec: &SensorSpec,
    model: &AxisModel,
    mode: Option<&StructuralMode>,
    samples: &[Sample],
) -> Result<Vec<f64>, SensorError> {
    let mount = spec.mount(model)?;
    let d = spec.unit_direction();
    let home_point = model.home.transform_point(mount);
    let point = |s: &Sample| s.point(model, mount, mode);
    let velocity = |s: &Sample| s.point_velocity(model, mount, mode);
    Ok(match spec.kind {
        SensorKind::Command => samples.iter().map(|s| s.cmd.pos).collect(),
        SensorKind::EncoderLinear => samples.iter().map(|s| s.scale).collect(),
        SensorKind::EncoderRotary => samples.iter().map(|s| s.motor).collect(),
        SensorKind::MotorForce => samples.iter().map(|s| s.force).collect(),
        SensorKind::Velocity => samples.iter().map(|s| velocity(s).dot(model.axis)).collect(),
        SensorKind::LaserLinear | SensorKind::LaserStraightness | SensorKind::LaserVector => {
            samples.iter().map(|s| d.dot(point(s) - home_point)).collect()
        }
        SensorKind::LaserAngular => samples.iter().map(|s| d.dot(s.rot)).collect(),
        SensorKind::Accelerometer => {
            let tilt = DQuat::from_scaled_axis(DVec3::from_array(spec.tilt));
            let axis_dir = model.home.rotation * (tilt * (model.axis_rotation * d));
            let mut out = Vec::with_capacity(samples.len());
            // Each sample's turn and mount velocity computed once (the difference reuses the last).
            let mut last: Option<(DVec3, f64)> = None;
            for s in samples {
                let turn = s.turn();
                let v = s.point_velocity_turned(turn, model, mount, mode);
                let a = last.map_or(DVec3::ZERO, |(v0, t0)| (v - v0) / (s.t - t0));
                last = Some((v, s.t));
                let proper = a + DVec3::new(0.0, 0.0, GRAVITY);
                out.push((turn * axis_dir).dot(proper));
            }
            out
        }
        SensorKind::Temperature => samples.iter().map(|_| 20.0 + 273.15).collect(),
        SensorKind::Pressure => samples.iter().map(|_| spec.air.unwrap_or(Air::REFERENCE).pressure).collect(),
        SensorKind::Humidity => samples.iter().map(|_| spec.air.unwrap_or(Air::REFERENCE).humidity / 100.0).collect(),
    })
}

/// Applies a sensor's errors and seeded noise to noise-free readings sampled at `fs` (Hz):
/// y = Q[HP((1 + s)·x + b + w) + n], n ~ N(0, σ²) with σ from `sigma` or ρ·√(fs/2), w the bias random
/// walk (increments N(0, rate²/fs), one per sample from the first, so w at sample k has variance
/// (k + 1)·rate²/fs), 1 + s the gain ([`SensorSpec::gain`]: the scale factor, and for lasers also the
/// air's Edlén error and the material normalisation error), Q quantisation.
pub fn apply_errors(spec: &SensorSpec, truth: &[f64], fs: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let sigma = if spec.noise_density > 0.0 { spec.noise_density * (fs / 2.0).sqrt() } else { spec.sigma };
    let gain = spec.gain();
    let mut out: Vec<f64> = truth.iter().map(|x| gain * x + spec.bias).collect();
    if spec.bias_drift > 0.0 && fs > 0.0 {
        let step = spec.bias_drift / fs.sqrt();
        let mut w = 0.0;
        for y in out.iter_mut() {
            let n: f64 = rng.sample(StandardNormal);
            w += step * n;
            *y += w;
        }
    }
    if spec.highpass > 0.0 && fs > 0.0 {
        out = highpass_first_order(&out, spec.highpass, fs);
    }
    for y in out.iter_mut() {
        let n: f64 = rng.sample(StandardNormal);
        *y += sigma * n;
        if spec.resolution > 0.0 {
            *y = quantise_reading(*y, spec.resolution);
        }
    }
    out
}

/// A reading quantised to the resolution `q` (> 0, in the reading's unit): k = round(y/q) counts, the
/// value k·q. When 1/q is a whole number of counts per unit (q = 1e-9 m: 10⁹ counts/m) the value is
/// computed as k/(1/q), the double nearest to the decimal k·q: 5102 counts of 1 nm are 5.102e-6 m, where
/// k·q carries q's representation error (5.1020000000000004e-6).
pub fn quantise_reading(y: f64, q: f64) -> f64 {
    let k = (y / q).round();
    let per_unit = (1.0 / q).round();
    if per_unit >= 1.0 && (per_unit * q - 1.0).abs() <= 1e-12 {
        k / per_unit
    } else {
        k * q
    }
}

/// First-order RC high-pass, discrete: `y[n] = α·(y[n−1] + x[n] − x[n−1])`, α = RC/(RC + T), RC = 1/(2π·fc),
/// started at steady state (`y[0] = 0`).
pub fn highpass_first_order(x: &[f64], fc: f64, fs: f64) -> Vec<f64> {
    let rc = 1.0 / (std::f64::consts::TAU * fc);
    let alpha = rc / (rc + 1.0 / fs);
    let mut y = Vec::with_capacity(x.len());
    for (i, &xi) in x.iter().enumerate() {
        y.push(if i == 0 { 0.0 } else { alpha * (y[i - 1] + xi - x[i - 1]) });
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reading_of_whole_nanometres_is_the_nearest_double_to_its_decimal() {
        // 5102 counts of 1 nm: k·q would be 5.1020000000000004e-6.
        assert_eq!(5102.0 * 1e-9, 5.1020000000000004e-6);
        assert_eq!(quantise_reading(5.1017e-6, 1e-9), 5.102e-6);
        assert_eq!(quantise_reading(-0.1090000000004, 1e-9), -0.109);
        // A resolution that is no whole number of counts per unit stays k·q.
        let q = 1.1690437793731688e-5;
        assert_eq!(quantise_reading(3.1 * q, q), 3.0 * q);
    }

    #[test]
    fn material_error_only_for_length_lasers_and_zero_by_default() {
        let mut s = SensorSpec::new("l", SensorKind::LaserLinear);
        // Defaults: 20 °C, steel, assumed = true: no error, gain exactly 1.
        assert_eq!((s.material_scale_error(), s.gain()), (0.0, 1.0));
        s.material_temperature = 22.0;
        s.assumed_material_temperature = Some(20.0);
        // α·2 K with T_a = 20 °C: exact, to rounding of 2.3e-5 (1e-20).
        assert!((s.material_scale_error() - 2.0 * STEEL_ALPHA).abs() < 1e-20);
        // Straightness and angular optics are not normalised to 20 °C.
        for kind in [SensorKind::LaserStraightness, SensorKind::LaserAngular, SensorKind::Accelerometer] {
            assert_eq!(SensorSpec { kind, ..s.clone() }.material_scale_error(), 0.0, "{kind:?}");
        }
    }
}
