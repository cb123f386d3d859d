//! The typed catalogue of named physical effects (FORMAT.md §2, DESIGN.md §4 "Effects").
//!
//! The same names are used in the truth of a scenario, in a user's model and in the diagnosis.
//! Each effect has a parameter struct in SI units; [`EffectSet`] holds the effects switched on for
//! a machine, with lookups by (name, axis) and range validation that names the key path of every
//! problem (`effects.backlash.value: expected a length in metres ≥ 0, got -4e-6`).
//! No file I/O here: the root package reads and writes the `vmt-model/1` TOML.

use crate::friction::StribeckLaw;
use crate::profile::{Profile, Term};
use crate::Axis;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

// The catalogue's rows (`Variant = "file_name"`, with its doc comment): [`EffectName`], and from
// the same rows [`EffectName::ALL`] (catalogue order, the order of FORMAT.md §2's table) and
// [`EffectName::as_str`] (snake_case, e.g. `cyclic_lead`): a new effect is one row here.
vmt_core::named_enum! {
    /// The name of a physical effect, as written in `[effects.NAME]` (FORMAT.md §2).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
    pub enum EffectName {
        /// Positioning error motion of the axis, ISO 230-1 EXX (m).
        Positioning = "positioning",
        /// Straightness error motion in the first transverse direction, EYX for the X axis (m).
        StraightnessY = "straightness_y",
        /// Straightness error motion in the second transverse direction, EZX for the X axis (m).
        StraightnessZ = "straightness_z",
        /// Roll: angular error motion about the axis itself, EAX for the X axis (rad).
        Roll = "roll",
        /// Pitch: angular error motion about the first transverse direction, EBX for X (rad).
        Pitch = "pitch",
        /// Yaw: angular error motion about the second transverse direction, ECX for X (rad).
        Yaw = "yaw",
        /// Squareness between the X and Y axes (rad).
        SquarenessXy = "squareness_xy",
        /// Squareness between the X and Z axes (rad).
        SquarenessXz = "squareness_xz",
        /// Squareness between the Y and Z axes (rad).
        SquarenessYz = "squareness_yz",
        /// Lost motion on reversal of the feed drive (m).
        Backlash = "backlash",
        /// Periodic lead error of the ball screw (m).
        CyclicLead = "cyclic_lead",
        /// Linear error of the feedback scale (m/m).
        ScaleError = "scale_error",
        /// Thermal expansion of the screw or scale, proportional to position and temperature rise.
        ThermalExpansion = "thermal_expansion",
        /// Thermal drift: a position-independent offset growing with time.
        ThermalDrift = "thermal_drift",
        /// Encoder interpolation error, periodic in the signal period.
        InterpolationError = "interpolation_error",
        /// Coulomb friction (N).
        Coulomb = "coulomb",
        /// Viscous friction (N·s/m).
        Viscous = "viscous",
        /// Stribeck friction curve.
        Stribeck = "stribeck",
        /// LuGre dynamic friction (Canudas de Wit et al. 1995).
        Lugre = "lugre",
        /// Following error from the servo loops.
        ServoLag = "servo_lag",
        /// A structural mode seen by accelerometers.
        Resonance = "resonance",
        /// Gravity seen by an accelerometer through the link's tilt (no parameters).
        GravityTilt = "gravity_tilt",
        /// Accelerometer bias random walk.
        AccelBiasDrift = "accel_bias_drift",
    }
}

/// The six error motions of an axis (ISO 230-1), the effects whose parameters are a [`Profile`] of
/// the axis position ([`EffectName::error_motion`]); for the X axis EXX, EYX, EZX, EAX, EBX, ECX.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorMotion {
    /// Positioning error motion along the axis, EXX for X (m).
    Positioning,
    /// Straightness in the first transverse direction, EYX for X (m).
    StraightnessY,
    /// Straightness in the second transverse direction, EZX for X (m).
    StraightnessZ,
    /// Roll, the angle about the axis itself, EAX for X (rad).
    Roll,
    /// Pitch, the angle about the first transverse direction, EBX for X (rad).
    Pitch,
    /// Yaw, the angle about the second transverse direction, ECX for X (rad).
    Yaw,
}

/// The six error motions as a pattern in a `match` over [`EffectName`] (`error_motions!() => …`):
/// the one list of them for the matches that treat them alike. The match stays exhaustive, so the
/// compiler still names it for a new effect.
#[macro_export]
macro_rules! error_motions {
    () => {
        $crate::effects::EffectName::Positioning
            | $crate::effects::EffectName::StraightnessY
            | $crate::effects::EffectName::StraightnessZ
            | $crate::effects::EffectName::Roll
            | $crate::effects::EffectName::Pitch
            | $crate::effects::EffectName::Yaw
    };
}

/// Returned by `EffectName::from_str` for a name that is not in the catalogue.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown effect `{name}`; known effects: {}", EffectName::known_list())]
pub struct UnknownEffect {
    /// The name that was given.
    pub name: String,
}

impl EffectName {
    /// The six error motions of an axis (ISO 230-1), in the order EXX, EYX, EZX, EAX, EBX, ECX.
    pub const ERROR_MOTIONS: [EffectName; 6] = [
        EffectName::Positioning,
        EffectName::StraightnessY,
        EffectName::StraightnessZ,
        EffectName::Roll,
        EffectName::Pitch,
        EffectName::Yaw,
    ];

    /// All names joined by ", ", for error messages.
    pub fn known_list() -> String {
        EffectName::ALL.iter().map(|n| n.as_str()).collect::<Vec<&str>>().join(", ")
    }

    /// True for the six error motions, whose parameters are a [`Profile`] of the axis position.
    pub fn is_error_motion(self) -> bool {
        self.error_motion().is_some()
    }

    /// True for the translational error motions (positioning, straightness: values in m); false
    /// for everything else. Roll, pitch and yaw are angles (rad).
    pub fn is_translational(self) -> bool {
        matches!(
            self.error_motion(),
            Some(ErrorMotion::Positioning | ErrorMotion::StraightnessY | ErrorMotion::StraightnessZ)
        )
    }

    /// True for the angular error motions (roll, pitch, yaw: values in rad); false for everything
    /// else.
    pub fn is_angular(self) -> bool {
        matches!(self.error_motion(), Some(ErrorMotion::Roll | ErrorMotion::Pitch | ErrorMotion::Yaw))
    }

    /// The error motion this effect is, `None` for every other effect. One arm per effect and no
    /// wildcard: the one place where a new effect says whether it is an error motion.
    pub fn error_motion(self) -> Option<ErrorMotion> {
        match self {
            EffectName::Positioning => Some(ErrorMotion::Positioning),
            EffectName::StraightnessY => Some(ErrorMotion::StraightnessY),
            EffectName::StraightnessZ => Some(ErrorMotion::StraightnessZ),
            EffectName::Roll => Some(ErrorMotion::Roll),
            EffectName::Pitch => Some(ErrorMotion::Pitch),
            EffectName::Yaw => Some(ErrorMotion::Yaw),
            EffectName::SquarenessXy
            | EffectName::SquarenessXz
            | EffectName::SquarenessYz
            | EffectName::Backlash
            | EffectName::CyclicLead
            | EffectName::ScaleError
            | EffectName::ThermalExpansion
            | EffectName::ThermalDrift
            | EffectName::InterpolationError
            | EffectName::Coulomb
            | EffectName::Viscous
            | EffectName::Stribeck
            | EffectName::Lugre
            | EffectName::ServoLag
            | EffectName::Resonance
            | EffectName::GravityTilt
            | EffectName::AccelBiasDrift => None,
        }
    }

    /// ISO 230-1 symbol of an error motion of `axis` (x, y or z), e.g. pitch of X → `EBX`.
    ///
    /// Convention (vmt's, for axes other than X): `straightness_y`/`straightness_z` are the first
    /// and second transverse directions in the order x, y, z with the axis itself skipped, and
    /// `pitch`/`yaw` the rotations about those same two directions; `roll` is about the axis.
    /// So for Y: EYY, EXY, EZY, EBY, EAY, ECY; for Z: EZZ, EXZ, EYZ, ECZ, EAZ, EBZ.
    /// `None` for effects that are not error motions.
    pub fn iso230_symbol(self, a: Axis) -> Option<String> {
        let [t1, t2] = a.transverse();
        let component = match self.error_motion()? {
            ErrorMotion::Positioning => a.iso_letter(),
            ErrorMotion::StraightnessY => t1.iso_letter(),
            ErrorMotion::StraightnessZ => t2.iso_letter(),
            ErrorMotion::Roll => a.rotation_letter(),
            ErrorMotion::Pitch => t1.rotation_letter(),
            ErrorMotion::Yaw => t2.rotation_letter(),
        };
        Some(format!("E{component}{}", a.iso_letter()))
    }
}

impl fmt::Display for EffectName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for EffectName {
    type Err = UnknownEffect;
    /// Parses the snake_case name of FORMAT.md §2 (exact, case-sensitive).
    fn from_str(s: &str) -> Result<EffectName, UnknownEffect> {
        EffectName::ALL.iter().copied().find(|n| n.as_str() == s).ok_or_else(|| UnknownEffect { name: s.to_string() })
    }
}

/// The admissible range of a scalar parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Range {
    /// Any finite number.
    Finite,
    /// x ≥ 0.
    NonNegative,
    /// x > 0.
    Positive,
    /// 0 ≤ x < 1 (a damping ratio of a resonance that still oscillates).
    UnitInterval,
}

impl Range {
    /// True if `x` is finite and inside the range.
    pub fn contains(self, x: f64) -> bool {
        x.is_finite()
            && match self {
                Range::Finite => true,
                Range::NonNegative => x >= 0.0,
                Range::Positive => x > 0.0,
                Range::UnitInterval => (0.0..1.0).contains(&x),
            }
    }

    /// The range as written in messages: "", " ≥ 0", " > 0", " in [0, 1)".
    pub fn describe(self) -> &'static str {
        match self {
            Range::Finite => "",
            Range::NonNegative => " ≥ 0",
            Range::Positive => " > 0",
            Range::UnitInterval => " in [0, 1)",
        }
    }
}

/// The physical unit of a scalar effect parameter (values are stored in SI); [`ParamUnit::display`]
/// prints a value in the unit a metrologist reads it in, with four significant digits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum ParamUnit {
    /// m; shown in µm below 1 mm, in mm below 1 m.
    Length,
    /// rad of a small angular error; shown in µrad.
    Angle,
    /// rad of a phase; shown in rad.
    Phase,
    /// N.
    Force,
    /// s.
    Time,
    /// m/s; shown in mm/s.
    Velocity,
    /// Hz.
    Frequency,
    /// m/m; shown in µm/m.
    Strain,
    /// 1/K; shown in µm/(m·K).
    ExpansionCoefficient,
    /// K.
    Temperature,
    /// N/m.
    Stiffness,
    /// N·s/m.
    Damping,
    /// 1/s.
    Rate,
    /// A pure number (ratio, exponent).
    Dimensionless,
    /// m/s²/√s.
    AccelRandomWalk,
    /// A gain whose unit depends on the other parameters given (servo `kv`); shown in SI.
    Gain,
}

impl ParamUnit {
    /// The physical bounds of a value in this unit (SI): (smallest magnitude of a strictly positive
    /// parameter, largest magnitude of any). A value outside them is a typo or a unit mistake, not a
    /// machine: a length or period of 1 nm to 100 m (an axis travel is at most [`MAX_LENGTH`]), an
    /// angular error up to 0.1 rad, a strain up to 1 % (10 000 µm/m), an expansion coefficient up to
    /// 1000 µm/(m·K) (metals 1–25, plastics up to ~200), time constants 1 ns to 1e9 s (30 years),
    /// velocities up to 100 m/s, frequencies 1 µHz to 1 MHz, forces up to 10 MN.
    pub fn limits(self) -> (f64, f64) {
        match self {
            ParamUnit::Length => (1e-9, MAX_LENGTH),
            ParamUnit::Angle => (1e-12, 0.1),
            ParamUnit::Phase => (0.0, 1e3),
            ParamUnit::Force => (1e-9, 1e7),
            ParamUnit::Time => (1e-9, 1e9),
            ParamUnit::Velocity => (1e-9, 100.0),
            ParamUnit::Frequency => (1e-6, 1e6),
            ParamUnit::Strain => (1e-12, 1e-2),
            ParamUnit::ExpansionCoefficient => (1e-12, 1e-3),
            ParamUnit::Temperature => (1e-6, 1e3),
            ParamUnit::Stiffness => (1e-9, 1e15),
            ParamUnit::Damping => (1e-9, 1e12),
            ParamUnit::Rate => (1e-9, 1e9),
            ParamUnit::Dimensionless => (1e-6, 1e3),
            ParamUnit::AccelRandomWalk => (0.0, 1e3),
            ParamUnit::Gain => (1e-9, 1e12),
        }
    }

    /// `v` (SI) in display units with four significant digits, e.g. `25.37 µm`, `10.49 mm`,
    /// `3.1 µrad`, `300.1 s`, `2.5 mm/s`.
    pub fn display(self, v: f64) -> String {
        let (scale, unit) = match self {
            ParamUnit::Length if v.abs() < 1e-3 => (1e6, "µm"),
            ParamUnit::Length if v.abs() < 1.0 => (1e3, "mm"),
            ParamUnit::Length => (1.0, "m"),
            ParamUnit::Angle => (1e6, "µrad"),
            ParamUnit::Phase => (1.0, "rad"),
            ParamUnit::Force => (1.0, "N"),
            ParamUnit::Time => (1.0, "s"),
            ParamUnit::Velocity => (1e3, "mm/s"),
            ParamUnit::Frequency => (1.0, "Hz"),
            ParamUnit::Strain => (1e6, "µm/m"),
            ParamUnit::ExpansionCoefficient => (1e6, "µm/(m·K)"),
            ParamUnit::Temperature => (1.0, "K"),
            ParamUnit::Stiffness => (1.0, "N/m"),
            ParamUnit::Damping => (1.0, "N·s/m"),
            ParamUnit::Rate => (1.0, "1/s"),
            ParamUnit::Dimensionless => (1.0, ""),
            ParamUnit::AccelRandomWalk => (1.0, "m/s²/√s"),
            ParamUnit::Gain => (1.0, "(SI)"),
        };
        let x = v * scale;
        let text = if !x.is_finite() || x == 0.0 || !(1e-3..1e7).contains(&x.abs()) {
            fmt_num(x)
        } else {
            // index: a count of decimals, not an index: |x| is in [1e-3, 1e7) here, so it is 0..=6.
            let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
            format!("{x:.decimals$}")
        };
        if unit.is_empty() {
            text
        } else {
            format!("{text} {unit}")
        }
    }
}

/// The largest length an effect parameter may have, m: an axis travel (vmt's readers bound
/// positions by the same 100 m).
pub const MAX_LENGTH: f64 = 100.0;

/// Description of one scalar parameter of an effect: its TOML key, what it is in SI units, its
/// admissible range, the starting value used when a model leaves it out under `fit = true`, and
/// whether a file must give it when the effect is not fitted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ParamSpec {
    /// TOML key, e.g. `value`.
    pub key: &'static str,
    /// What it is, for messages: "a length in metres".
    pub quantity: &'static str,
    /// Its physical unit, for display ([`ParamUnit::display`]).
    pub unit: ParamUnit,
    /// Admissible range.
    pub range: Range,
    /// Starting value for a fit when the file gives none (SI).
    pub default: f64,
    /// Must be given when `fit` is false. Optional parameters without a value stay unset
    /// (`Option::None`) or take `default`.
    pub required: bool,
}

const fn spec(
    key: &'static str,
    quantity: &'static str,
    unit: ParamUnit,
    range: Range,
    default: f64,
    required: bool,
) -> ParamSpec {
    ParamSpec { key, quantity, unit, range, default, required }
}

const LENGTH: &str = "a length in metres";
const ANGLE: &str = "an angle in radians";
const FORCE: &str = "a force in newtons";
const TAU: &str = "a time constant in seconds";
const VISC: &str = "a viscous coefficient in N·s/m";

static SQUARENESS_SPECS: [ParamSpec; 1] = [spec("value", ANGLE, ParamUnit::Angle, Range::Finite, 0.0, true)];
static BACKLASH_SPECS: [ParamSpec; 1] = [spec("value", LENGTH, ParamUnit::Length, Range::NonNegative, 0.0, true)];
static CYCLIC_LEAD_SPECS: [ParamSpec; 3] = [
    spec("period", "a screw lead in metres", ParamUnit::Length, Range::Positive, 0.010, true),
    spec("amplitude", LENGTH, ParamUnit::Length, Range::NonNegative, 0.0, true),
    spec("phase", "a phase in radians", ParamUnit::Phase, Range::Finite, 0.0, false),
];
static SCALE_ERROR_SPECS: [ParamSpec; 1] =
    [spec("value", "a strain in m/m", ParamUnit::Strain, Range::Finite, 0.0, true)];
static THERMAL_EXPANSION_SPECS: [ParamSpec; 3] = [
    spec("alpha", "an expansion coefficient in 1/K", ParamUnit::ExpansionCoefficient, Range::Finite, 11.5e-6, true),
    spec("delta_t", "a temperature rise in kelvin", ParamUnit::Temperature, Range::Finite, 0.0, true),
    spec("tau", TAU, ParamUnit::Time, Range::NonNegative, 1800.0, true),
];
static THERMAL_DRIFT_SPECS: [ParamSpec; 2] = [
    spec("value", LENGTH, ParamUnit::Length, Range::Finite, 0.0, true),
    spec("tau", TAU, ParamUnit::Time, Range::NonNegative, 1800.0, true),
];
static INTERPOLATION_SPECS: [ParamSpec; 3] = [
    spec("period", "a signal period in metres", ParamUnit::Length, Range::Positive, 20e-6, true),
    spec("amplitude", LENGTH, ParamUnit::Length, Range::NonNegative, 0.0, true),
    spec("phase", "a phase in radians", ParamUnit::Phase, Range::Finite, 0.0, false),
];
static COULOMB_SPECS: [ParamSpec; 1] = [spec("fc", FORCE, ParamUnit::Force, Range::NonNegative, 0.0, true)];
static VISCOUS_SPECS: [ParamSpec; 1] = [spec("fv", VISC, ParamUnit::Damping, Range::NonNegative, 0.0, true)];
static STRIBECK_SPECS: [ParamSpec; 4] = [
    spec("fc", FORCE, ParamUnit::Force, Range::NonNegative, 0.0, false),
    spec("fs", FORCE, ParamUnit::Force, Range::NonNegative, 0.0, true),
    spec("vs", "a Stribeck velocity in m/s", ParamUnit::Velocity, Range::Positive, 1e-3, true),
    spec("shape", "a Stribeck shape exponent", ParamUnit::Dimensionless, Range::Positive, 2.0, false),
];
static LUGRE_SPECS: [ParamSpec; 7] = [
    spec("sigma0", "a bristle stiffness in N/m", ParamUnit::Stiffness, Range::Positive, 1e5, true),
    spec("sigma1", "a bristle damping in N·s/m", ParamUnit::Damping, Range::NonNegative, 316.227_766_016_837_94, true),
    spec("sigma2", VISC, ParamUnit::Damping, Range::NonNegative, 0.0, true),
    spec("fc", FORCE, ParamUnit::Force, Range::NonNegative, 0.0, true),
    spec("fs", FORCE, ParamUnit::Force, Range::NonNegative, 0.0, true),
    spec("vs", "a Stribeck velocity in m/s", ParamUnit::Velocity, Range::Positive, 1e-3, true),
    spec("shape", "a Stribeck shape exponent", ParamUnit::Dimensionless, Range::Positive, 2.0, false),
];
static SERVO_LAG_SPECS: [ParamSpec; 3] = [
    spec("kv", "a gain (1/s alone; N·s/m with kp)", ParamUnit::Gain, Range::Positive, 30.0, true),
    spec("kp", "a position-loop gain in 1/s", ParamUnit::Rate, Range::Positive, 30.0, false),
    spec("ki", "a velocity-loop integral gain in N/m", ParamUnit::Stiffness, Range::NonNegative, 0.0, false),
];
static RESONANCE_SPECS: [ParamSpec; 2] = [
    spec("frequency", "a frequency in Hz", ParamUnit::Frequency, Range::Positive, 100.0, true),
    spec("damping", "a damping ratio", ParamUnit::Dimensionless, Range::UnitInterval, 0.02, true),
];
static NO_SCALARS: [ParamSpec; 0] = [];
static ACCEL_BIAS_DRIFT_SPECS: [ParamSpec; 1] =
    [spec("rate", "a random-walk rate in m/s²/√s", ParamUnit::AccelRandomWalk, Range::NonNegative, 0.0, true)];

/// What [`effect_params!`] asks of every parameter struct: its scalar parameters by TOML key and
/// its starting values.
trait Params: Sized {
    /// Value of the scalar parameter `key` (SI), `None` if unknown or unset.
    fn scalar(&self, key: &str) -> Option<f64>;
    /// Sets the scalar parameter `key` (SI); false if there is no such key.
    fn set_scalar(&mut self, key: &str, value: f64) -> bool;
    /// The starting values: `default(key)` for every scalar, optional ones unset, lists empty.
    fn starting(default: &dyn Fn(&str) -> f64) -> Self;
    /// The profile of an error motion, `None` for every other parameter set.
    fn as_profile(&self) -> Option<&Profile> {
        None
    }
}

/// An error motion's parameter is its profile: no scalar parameters, zero to start with.
impl Params for Profile {
    fn scalar(&self, _: &str) -> Option<f64> {
        None
    }
    fn set_scalar(&mut self, _: &str, _: f64) -> bool {
        false
    }
    fn starting(_: &dyn Fn(&str) -> f64) -> Profile {
        Profile::zero()
    }
    fn as_profile(&self) -> Option<&Profile> {
        Some(self)
    }
}

/// Generates `get(key)` / `set(key, value)` for a parameter struct from its f64 and Option<f64>
/// fields, so that readers, writers, validators and fitters can address parameters by TOML key,
/// and its [`Params`] (starting values; `lists` are list-valued fields, empty to start with).
macro_rules! keyed_params {
    ($t:ty { $($f:ident),* } optional { $($o:ident),* } $(lists { $($l:ident),* })?) => {
        impl $t {
            /// Value of the scalar parameter `key` (SI), `None` if unknown or unset.
            pub fn get(&self, key: &str) -> Option<f64> {
                match key {
                    $(stringify!($f) => Some(self.$f),)*
                    $(stringify!($o) => self.$o,)*
                    _ => None,
                }
            }
            /// Sets the scalar parameter `key` (SI); false if the struct has no such key.
            pub fn set(&mut self, key: &str, value: f64) -> bool {
                match key {
                    $(stringify!($f) => { self.$f = value; true })*
                    $(stringify!($o) => { self.$o = Some(value); true })*
                    _ => false,
                }
            }
        }
        impl Params for $t {
            fn scalar(&self, key: &str) -> Option<f64> {
                self.get(key)
            }
            fn set_scalar(&mut self, key: &str, value: f64) -> bool {
                self.set(key, value)
            }
            fn starting(default: &dyn Fn(&str) -> f64) -> Self {
                Self { $($f: default(stringify!($f)),)* $($o: None,)* $($($l: Vec::new(),)*)? }
            }
        }
    };
}

/// Squareness between two axes: a position-independent angle, rad (ISO 230-1 EC0X etc.).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Squareness {
    /// Out-of-squareness angle, rad.
    pub value: f64,
}
keyed_params!(Squareness { value } optional {});

/// Backlash: lost motion on reversal, a dead zone of width `value` in the screw–nut contact, m.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Backlash {
    /// Width of the dead zone (lost motion), m, ≥ 0.
    pub value: f64,
}
keyed_params!(Backlash { value } optional {});

/// A higher harmonic of the cyclic lead error: amplitude·sin(2π·order·x/period + phase).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeadHarmonic {
    /// Harmonic number of the screw period, ≥ 2.
    pub order: u32,
    /// Amplitude, m, ≥ 0.
    pub amplitude: f64,
    /// Phase, rad.
    pub phase: f64,
}

/// Periodic lead error of a ball screw (ISO 3408-3 "v_2π"):
/// δ(x) = A·sin(2πx/p + φ) + Σ_k A_k·sin(2πkx/p + φ_k).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CyclicLead {
    /// Screw lead p, m, > 0.
    pub period: f64,
    /// Amplitude A of the fundamental, m, ≥ 0.
    pub amplitude: f64,
    /// Phase φ of the fundamental, rad.
    pub phase: f64,
    /// Optional higher harmonics.
    pub harmonics: Vec<LeadHarmonic>,
}
keyed_params!(CyclicLead { period, amplitude, phase } optional {} lists { harmonics });

impl CyclicLead {
    /// Lead error δ(x), m, at axis position x (m): A·sin(2πx/p + φ) + Σ A_k·sin(2πkx/p + φ_k).
    pub fn value(&self, x: f64) -> f64 {
        let k = std::f64::consts::TAU / self.period;
        let base = self.amplitude * (k * x + self.phase).sin();
        self.harmonics.iter().fold(base, |acc, h| acc + h.amplitude * (k * f64::from(h.order) * x + h.phase).sin())
    }
}

/// Linear error of the feedback scale: δ(x) = value·x.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleError {
    /// Scale error, m/m (1e-6 = 1 ppm).
    pub value: f64,
}
keyed_params!(ScaleError { value } optional {});

impl ScaleError {
    /// δ(x) = value·x, m.
    pub fn value_at(&self, x: f64) -> f64 {
        self.value * x
    }
}

/// Thermal expansion (FORMAT.md §2): δ(x, t) = α·x·ΔT(t), ΔT(t) = ΔT∞·(1 − exp(−t/τ)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ThermalExpansion {
    /// Expansion coefficient α, 1/K (steel about 11.5e-6).
    pub alpha: f64,
    /// Final temperature rise ΔT∞, K.
    pub delta_t: f64,
    /// Time constant τ, s, ≥ 0 (0: a step at t = 0).
    pub tau: f64,
}
keyed_params!(ThermalExpansion { alpha, delta_t, tau } optional {});

impl ThermalExpansion {
    /// δ(x, t) = α·x·ΔT∞·(1 − exp(−t/τ)), m, for x in m and t in s (t < 0: no expansion).
    pub fn value(&self, x: f64, t: f64) -> f64 {
        self.alpha * x * self.delta_t * rise(t, self.tau)
    }
}

/// 1 − exp(−t/τ) for t ≥ 0 (a step when τ = 0), 0 before t = 0: the rise of the thermal effects.
pub fn rise(t: f64, tau: f64) -> f64 {
    if t <= 0.0 {
        0.0
    } else if tau <= 0.0 {
        1.0
    } else {
        -(-t / tau).exp_m1()
    }
}

/// Thermal drift (FORMAT.md §2): δ(t) = d∞·(1 − exp(−t/τ)), independent of position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ThermalDrift {
    /// Final drift d∞, m.
    pub value: f64,
    /// Time constant τ, s, ≥ 0.
    pub tau: f64,
}
keyed_params!(ThermalDrift { value, tau } optional {});

impl ThermalDrift {
    /// δ(t) = d∞·(1 − exp(−t/τ)), m, t in s.
    pub fn value_at(&self, t: f64) -> f64 {
        self.value * rise(t, self.tau)
    }
}

/// Encoder interpolation error, periodic in the signal period (DESIGN.md §5, e.g. 20 µm):
/// δ(x) = A·sin(2πx/p + φ).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InterpolationError {
    /// Signal period p, m, > 0.
    pub period: f64,
    /// Amplitude A, m, ≥ 0.
    pub amplitude: f64,
    /// Phase φ, rad (optional in files, default 0).
    pub phase: f64,
}
keyed_params!(InterpolationError { period, amplitude, phase } optional {});

impl InterpolationError {
    /// δ(x) = A·sin(2πx/p + φ), m.
    pub fn value(&self, x: f64) -> f64 {
        self.amplitude * (std::f64::consts::TAU * x / self.period + self.phase).sin()
    }
}

/// Coulomb friction F = Fc·sgn(v).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coulomb {
    /// Coulomb (kinetic) friction force Fc, N, ≥ 0.
    pub fc: f64,
}
keyed_params!(Coulomb { fc } optional {});

/// Viscous friction F = Fv·v.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viscous {
    /// Viscous coefficient Fv, N·s/m, ≥ 0.
    pub fv: f64,
}
keyed_params!(Viscous { fv } optional {});

/// Stribeck curve (DESIGN.md §4): F = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)].
/// FORMAT.md §2 lists `fs`, `vs`, `shape`; `fc` may be given here, else it is the `fc` of the
/// `coulomb` effect on the same axis (0 without one), see [`EffectSet::friction`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stribeck {
    /// Coulomb level Fc, N, ≥ 0; `None`: taken from the `coulomb` effect.
    pub fc: Option<f64>,
    /// Static (break-away) friction Fs, N, ≥ 0.
    pub fs: f64,
    /// Stribeck velocity vs, m/s, > 0.
    pub vs: f64,
    /// Shape exponent δ, > 0 (optional in files, default 2).
    pub shape: f64,
}
keyed_params!(Stribeck { fs, vs, shape } optional { fc });

/// LuGre friction (Canudas de Wit, Olsson, Åström, Lischinsky 1995):
/// dz/dt = v − σ0·|v|·z/g(v), g(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ), F = σ0·z + σ1·dz/dt + σ2·v.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lugre {
    /// Bristle stiffness σ0, N/m, > 0.
    pub sigma0: f64,
    /// Bristle damping σ1, N·s/m, ≥ 0.
    pub sigma1: f64,
    /// Viscous coefficient σ2, N·s/m, ≥ 0.
    pub sigma2: f64,
    /// Coulomb level Fc, N, ≥ 0.
    pub fc: f64,
    /// Static friction Fs, N, ≥ 0.
    pub fs: f64,
    /// Stribeck velocity vs, m/s, > 0.
    pub vs: f64,
    /// Shape exponent δ (optional in files, default 2 as in the 1995 paper).
    pub shape: f64,
}
keyed_params!(Lugre { sigma0, sigma1, sigma2, fc, fs, vs, shape } optional {});

/// Servo lag: the following error of the position loop.
///
/// With `kv` alone: the CNC "Kv factor" in 1/s, following error e = v/kv at constant feed v.
/// With `kp` given: the cascade loops of DESIGN.md §4, position P gain `kp` (1/s), velocity PI
/// loop with proportional gain `kv` (N·s/m) and integral gain `ki` (N/m, 0 if absent).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ServoLag {
    /// Kv factor (1/s) without `kp`; velocity-loop proportional gain (N·s/m) with `kp`.
    pub kv: f64,
    /// Position-loop gain, 1/s (selects the cascade form).
    pub kp: Option<f64>,
    /// Velocity-loop integral gain, N/m (cascade form only).
    pub ki: Option<f64>,
}
keyed_params!(ServoLag { kv } optional { kp, ki });

/// A structural mode: natural frequency f (Hz) and damping ratio ζ, transfer function
/// ω²/(s² + 2ζωs + ω²), ω = 2πf.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Resonance {
    /// Natural frequency f, Hz, > 0.
    pub frequency: f64,
    /// Damping ratio ζ, in [0, 1).
    pub damping: f64,
}
keyed_params!(Resonance { frequency, damping } optional {});

/// Accelerometer bias random walk: b(t) = rate·W(t), W a standard Wiener process.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AccelBiasDrift {
    /// Random-walk rate, m/s² per √s, ≥ 0.
    pub rate: f64,
}
keyed_params!(AccelBiasDrift { rate } optional {});

/// Defines [`EffectParams`] from the rows of the table below (one row a parameter set: its variant
/// and struct, the effects it serves as a pattern, their scalar [`ParamSpec`]s), and from the same
/// rows [`param_specs`], [`EffectParams::default_for`], [`EffectParams::fits`], [`EffectParams::get`],
/// [`EffectParams::set`] and [`EffectParams::profile`]. The matches it writes over [`EffectName`]
/// have no wildcard: an effect without a row is named by the compiler here. The one variant without
/// parameters (`gravity_tilt`) follows the rows after `;`.
macro_rules! effect_params {
    (
        $($(#[$doc:meta])* $variant:ident($t:ty) for $names:pat => $specs:expr,)*
        ; $(#[$unit_doc:meta])* $unit:ident for $unit_name:pat => $unit_specs:expr,
    ) => {
        /// The parameters of one effect. The variant must match the effect's name
        /// ([`EffectParams::fits`]); error motions carry a [`Profile`] (m, or rad for roll/pitch/yaw).
        #[derive(Clone, Debug, PartialEq)]
        pub enum EffectParams {
            $($(#[$doc])* $variant($t),)*
            $(#[$unit_doc])* $unit,
        }

        /// The scalar parameters of an effect, in the order they are written. Error motions (whose
        /// parameter is a profile), `gravity_tilt` (none) and the list-valued `cyclic_lead.harmonics`
        /// are not scalar and are not listed.
        pub fn param_specs(name: EffectName) -> &'static [ParamSpec] {
            match name {
                $($names => &$specs,)*
                $unit_name => &$unit_specs,
            }
        }

        impl EffectParams {
            /// The starting values of `name`'s parameters ([`ParamSpec::default`]; a zero profile
            /// for error motions; optional parameters unset, lists empty): what a fit starts from
            /// when a model gives none.
            pub fn default_for(name: EffectName) -> EffectParams {
                let d = |key: &str| param_specs(name).iter().find(|s| s.key == key).map_or(0.0, |s| s.default);
                match name {
                    $($names => EffectParams::$variant(<$t as Params>::starting(&d)),)*
                    $unit_name => EffectParams::$unit,
                }
            }

            /// True if this parameter variant belongs to the effect `name`.
            pub fn fits(&self, name: EffectName) -> bool {
                match self {
                    $(EffectParams::$variant(_) => matches!(name, $names),)*
                    EffectParams::$unit => matches!(name, $unit_name),
                }
            }

            /// Value of the scalar parameter `key` (SI); `None` for unknown keys, unset optional
            /// parameters, profiles and lists.
            pub fn get(&self, key: &str) -> Option<f64> {
                match self {
                    $(EffectParams::$variant(p) => p.scalar(key),)*
                    EffectParams::$unit => None,
                }
            }

            /// Sets the scalar parameter `key` (SI); false if there is no such scalar parameter.
            pub fn set(&mut self, key: &str, value: f64) -> bool {
                match self {
                    $(EffectParams::$variant(p) => p.set_scalar(key, value),)*
                    EffectParams::$unit => false,
                }
            }

            /// The profile of an error motion, `None` for other effects.
            pub fn profile(&self) -> Option<&Profile> {
                match self {
                    $(EffectParams::$variant(p) => p.as_profile(),)*
                    EffectParams::$unit => None,
                }
            }
        }
    };
}

effect_params! {
    /// Error motion as a function of axis position (positioning … yaw).
    ErrorMotion(Profile) for error_motions!() => NO_SCALARS,
    /// squareness_xy / _xz / _yz.
    Squareness(Squareness) for EffectName::SquarenessXy | EffectName::SquarenessXz | EffectName::SquarenessYz
        => SQUARENESS_SPECS,
    /// backlash.
    Backlash(Backlash) for EffectName::Backlash => BACKLASH_SPECS,
    /// cyclic_lead.
    CyclicLead(CyclicLead) for EffectName::CyclicLead => CYCLIC_LEAD_SPECS,
    /// scale_error.
    ScaleError(ScaleError) for EffectName::ScaleError => SCALE_ERROR_SPECS,
    /// thermal_expansion.
    ThermalExpansion(ThermalExpansion) for EffectName::ThermalExpansion => THERMAL_EXPANSION_SPECS,
    /// thermal_drift.
    ThermalDrift(ThermalDrift) for EffectName::ThermalDrift => THERMAL_DRIFT_SPECS,
    /// interpolation_error.
    InterpolationError(InterpolationError) for EffectName::InterpolationError => INTERPOLATION_SPECS,
    /// coulomb.
    Coulomb(Coulomb) for EffectName::Coulomb => COULOMB_SPECS,
    /// viscous.
    Viscous(Viscous) for EffectName::Viscous => VISCOUS_SPECS,
    /// stribeck.
    Stribeck(Stribeck) for EffectName::Stribeck => STRIBECK_SPECS,
    /// lugre.
    Lugre(Lugre) for EffectName::Lugre => LUGRE_SPECS,
    /// servo_lag.
    ServoLag(ServoLag) for EffectName::ServoLag => SERVO_LAG_SPECS,
    /// resonance.
    Resonance(Resonance) for EffectName::Resonance => RESONANCE_SPECS,
    /// accel_bias_drift.
    AccelBiasDrift(AccelBiasDrift) for EffectName::AccelBiasDrift => ACCEL_BIAS_DRIFT_SPECS,
    ;
    /// gravity_tilt: follows from the angles, no parameters.
    GravityTilt for EffectName::GravityTilt => NO_SCALARS,
}

impl EffectParams {
    /// The set scalar parameters as (key, value) pairs in [`param_specs`] order, for JSON output
    /// (`"params": {"value": 6.1e-6}`) and for fitters that work on a parameter vector.
    pub fn scalars(&self, name: EffectName) -> Vec<(&'static str, f64)> {
        param_specs(name).iter().filter_map(|s| self.get(s.key).map(|v| (s.key, v))).collect()
    }
}

/// One problem found by validation: the key path (relative to where the effect or set sits)
/// and what was expected.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Problem {
    /// Key path, e.g. `effects.backlash.value` or `harmonics[0].wavelength`.
    pub key: String,
    /// What was expected and what was found.
    pub message: String,
}

/// A number for messages: short scientific notation for small or large magnitudes (`-4e-6`),
/// plain otherwise (`0.25`); always the shortest digits that round-trip.
pub fn fmt_num(x: f64) -> String {
    let a = x.abs();
    if x.is_finite() && a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// One effect switched on for one axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Effect {
    /// Which effect.
    pub name: EffectName,
    /// The axis it acts on (files write `x`, `y` or `z`).
    pub axis: Axis,
    /// Its parameters (variant matching `name`).
    pub params: EffectParams,
}

impl Effect {
    /// The effect `name` on `axis` with the starting values of [`EffectParams::default_for`].
    pub fn default_for(name: EffectName, axis: Axis) -> Effect {
        Effect { name, axis, params: EffectParams::default_for(name) }
    }

    /// An error motion (positioning … yaw) with the given profile.
    pub fn error_motion(name: EffectName, axis: Axis, profile: Profile) -> Effect {
        Effect { name, axis, params: EffectParams::ErrorMotion(profile) }
    }

    /// Checks every parameter against its admissible range (and that the
    /// parameter variant matches the name). Keys are relative to the effect's table.
    pub fn validate(&self) -> Vec<Problem> {
        let mut out: Vec<Problem> = Vec::new();
        let mut bad = |key: String, message: String| out.push(Problem { key, message });
        if !self.params.fits(self.name) {
            bad(String::new(), format!("internal: parameters of another effect given for `{}`", self.name));
            return out;
        }
        for s in param_specs(self.name) {
            if let Some(v) = self.params.get(s.key) {
                let (min_positive, max) = s.unit.limits();
                if !s.range.contains(v) {
                    bad(
                        s.key.to_string(),
                        format!("expected {}{}, got {}", s.quantity, s.range.describe(), fmt_num(v)),
                    );
                } else if v.abs() > max || (s.range == Range::Positive && v < min_positive) {
                    bad(
                        s.key.to_string(),
                        format!(
                            "expected {}{} between {} and {} (physical bounds), got {} (a unit mistake?)",
                            s.quantity,
                            s.range.describe(),
                            s.unit.display(if s.range == Range::Positive { min_positive } else { -max }),
                            s.unit.display(max),
                            fmt_num(v)
                        ),
                    );
                }
            }
        }
        // Beyond the scalars checked above from `param_specs` (every effect's, generically), three
        // effects carry structure of their own: a profile, cyclic-lead harmonics, the cascade gains.
        if let EffectParams::ErrorMotion(p) = &self.params {
            let (q, unit) =
                if self.name.is_translational() { (LENGTH, ParamUnit::Length) } else { (ANGLE, ParamUnit::Angle) };
            validate_profile(p, q, unit, &mut bad);
        }
        if let EffectParams::CyclicLead(c) = &self.params {
            for (i, h) in c.harmonics.iter().enumerate() {
                if h.order < 2 {
                    bad(format!("harmonics[{i}].order"), format!("expected a harmonic number ≥ 2, got {}", h.order));
                }
                if !Range::NonNegative.contains(h.amplitude) {
                    bad(
                        format!("harmonics[{i}].amplitude"),
                        format!("expected {LENGTH} ≥ 0, got {}", fmt_num(h.amplitude)),
                    );
                }
                if !h.phase.is_finite() {
                    bad(
                        format!("harmonics[{i}].phase"),
                        format!("expected a phase in radians, got {}", fmt_num(h.phase)),
                    );
                }
            }
        }
        if let EffectParams::ServoLag(s) = &self.params {
            if s.ki.is_some() && s.kp.is_none() {
                bad(
                    "ki".into(),
                    "the cascade gains go together: `ki` needs `kp` (and `kv` is then the \
                     velocity-loop gain in N·s/m)"
                        .into(),
                );
            }
        }
        out
    }
}

/// Range checks of a profile's terms; `quantity` names the unit of the error motion.
/// Most coefficients of a `poly` term: a smooth error motion needs a few; monomials beyond degree ~20
/// are ill-conditioned anyway, and every term is evaluated at every physics step (size budget).
pub const MAX_POLY_TERMS: usize = 64;
/// Most `harmonics` of one profile (each is a sine evaluated at every physics step).
pub const MAX_HARMONICS: usize = 4096;
/// Most rows of a profile `table`.
pub const MAX_TABLE_ROWS: usize = 1_000_000;

fn validate_profile(p: &Profile, quantity: &str, unit: ParamUnit, bad: &mut dyn FnMut(String, String)) {
    // An error motion's size: |e| up to an axis travel for a length would already be absurd; the
    // amplitude bound is the unit's physical limit (lengths ≤ 100 m, angles ≤ 0.1 rad), wavelengths
    // and correlation lengths are lengths of 1 nm to 100 m.
    let (_, max_size) = unit.limits();
    let (min_len, max_len) = ParamUnit::Length.limits();
    let length_ok = |x: f64| x.is_finite() && (min_len..=max_len).contains(&x);
    for term in &p.terms {
        match term {
            Term::Poly(c) => {
                if c.len() > MAX_POLY_TERMS {
                    bad(
                        "poly".into(),
                        format!(
                            "expected at most {MAX_POLY_TERMS} coefficients (a smooth error motion), got {}",
                            c.len()
                        ),
                    );
                    continue;
                }
                for (i, ci) in c.iter().enumerate() {
                    if !ci.is_finite() {
                        bad(format!("poly[{i}]"), format!("expected a finite coefficient, got {ci}"));
                    }
                }
            }
            Term::Harmonics(h) => {
                if h.len() > MAX_HARMONICS {
                    bad("harmonics".into(), format!("expected at most {MAX_HARMONICS} harmonics, got {}", h.len()));
                    continue;
                }
                for (i, hi) in h.iter().enumerate() {
                    if !(hi.amplitude.is_finite() && hi.amplitude.abs() <= max_size) {
                        bad(
                            format!("harmonics[{i}].amplitude"),
                            format!(
                                "expected {quantity} of at most {} in size, got {}",
                                unit.display(max_size),
                                fmt_num(hi.amplitude)
                            ),
                        );
                    }
                    if !length_ok(hi.wavelength) {
                        bad(
                            format!("harmonics[{i}].wavelength"),
                            format!(
                                "expected a wavelength in metres between {} and {}, got {}",
                                fmt_num(min_len),
                                fmt_num(max_len),
                                fmt_num(hi.wavelength)
                            ),
                        );
                    }
                    if !hi.phase.is_finite() {
                        bad(format!("harmonics[{i}].phase"), format!("expected a phase in radians, got {}", hi.phase));
                    }
                }
            }
            Term::Random { spec, .. } => {
                if !(Range::NonNegative.contains(spec.rms) && spec.rms <= max_size) {
                    bad(
                        "random.rms".into(),
                        format!(
                            "expected {quantity} ≥ 0 and at most {}, got {}",
                            unit.display(max_size),
                            fmt_num(spec.rms)
                        ),
                    );
                }
                if !length_ok(spec.correlation_length) {
                    bad(
                        "random.correlation_length".into(),
                        format!(
                            "expected a length in metres between {} and {}, got {}",
                            fmt_num(min_len),
                            fmt_num(max_len),
                            fmt_num(spec.correlation_length)
                        ),
                    );
                }
            }
            Term::Table { x, y } => {
                if x.len() > MAX_TABLE_ROWS {
                    bad("table".into(), format!("expected at most {MAX_TABLE_ROWS} rows, got {}", x.len()));
                    continue;
                }
                if let Some(i) = y.iter().position(|v| v.abs() > max_size) {
                    bad(
                        "table".into(),
                        format!(
                            "expected {quantity} of at most {} in size, got {} at entry {i}",
                            unit.display(max_size),
                            fmt_num(y[i])
                        ),
                    );
                }
                if x.len() != y.len() || x.len() < 2 {
                    bad(
                        "table".into(),
                        format!(
                            "expected at least two (position, value) rows, got {} positions and \
                             {} values",
                            x.len(),
                            y.len()
                        ),
                    );
                    continue;
                }
                if let Some(i) = x.iter().chain(y.iter()).position(|v| !v.is_finite()) {
                    bad("table".into(), format!("expected finite numbers, got a non-finite one at entry {i}"));
                }
                if let Some(i) = x.windows(2).position(|w| w[1] <= w[0]) {
                    bad(
                        "table".into(),
                        format!(
                            "positions must be strictly increasing, got {} after {}",
                            fmt_num(x[i + 1]),
                            fmt_num(x[i])
                        ),
                    );
                }
            }
        }
    }
}

/// The friction law of one axis, assembled from its `coulomb`, `viscous`, `stribeck` and `lugre`
/// effects: the steady-sliding [`StribeckLaw`] F(v) = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v
/// (DESIGN.md §4), plus the LuGre bristle parameters when a `lugre` effect is present.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrictionLaw {
    /// The steady-sliding curve: Fs = Fc without a Stribeck or LuGre effect; Fv = `viscous.fv` plus
    /// `lugre.sigma2`; δ is the effects' `shape`.
    pub steady: StribeckLaw,
    /// LuGre [σ0 (N/m), σ1 (N·s/m)] when a `lugre` effect is present.
    pub lugre: Option<[f64; 2]>,
}

/// The effects switched on for a machine (the truth of a scenario, or a model's effects).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EffectSet {
    /// The effects; at most one per (name, axis).
    pub effects: Vec<Effect>,
}

impl EffectSet {
    /// The effect `name` on `axis`, if switched on.
    pub fn get(&self, name: EffectName, axis: Axis) -> Option<&Effect> {
        self.effects.iter().find(|e| e.name == name && e.axis == axis)
    }

    /// Mutable access to the effect `name` on `axis`.
    pub fn get_mut(&mut self, name: EffectName, axis: Axis) -> Option<&mut Effect> {
        self.effects.iter_mut().find(|e| e.name == name && e.axis == axis)
    }

    /// The profile of the error motion `name` on `axis`, if switched on.
    pub fn error_motion(&self, name: EffectName, axis: Axis) -> Option<&Profile> {
        self.get(name, axis).and_then(|e| e.params.profile())
    }

    /// Adds an effect, replacing (and returning) one with the same name and axis.
    pub fn insert(&mut self, effect: Effect) -> Option<Effect> {
        match self.effects.iter_mut().find(|e| e.name == effect.name && e.axis == effect.axis) {
            Some(slot) => Some(std::mem::replace(slot, effect)),
            None => {
                self.effects.push(effect);
                None
            }
        }
    }

    /// Removes and returns the effect `name` on `axis`.
    pub fn remove(&mut self, name: EffectName, axis: Axis) -> Option<Effect> {
        let i = self.effects.iter().position(|e| e.name == name && e.axis == axis)?;
        Some(self.effects.remove(i))
    }

    /// Key path of effect `i` as a `vmt-model/1` file writes it: `effects.NAME` when the name
    /// occurs once, `effects.NAME[k]` (k-th of that name) when it occurs on several axes.
    pub fn key_path(&self, i: usize) -> String {
        let name = self.effects[i].name;
        let same: Vec<usize> = (0..self.effects.len()).filter(|&j| self.effects[j].name == name).collect();
        if same.len() == 1 {
            format!("effects.{name}")
        } else {
            let k = same.iter().position(|&j| j == i).unwrap_or(0);
            format!("effects.{name}[{k}]")
        }
    }

    /// Validates every effect (ranges, axis) and that no (name, axis) occurs twice; keys are
    /// full paths such as `effects.backlash.value`.
    pub fn validate(&self) -> Vec<Problem> {
        let mut out: Vec<Problem> = Vec::new();
        for (i, e) in self.effects.iter().enumerate() {
            let path = self.key_path(i);
            if self.effects[..i].iter().any(|f| f.name == e.name && f.axis == e.axis) {
                out.push(Problem {
                    key: path.clone(),
                    message: format!("`{}` is given twice for axis {}", e.name, e.axis),
                });
            }
            for p in e.validate() {
                let key = if p.key.is_empty() { path.clone() } else { format!("{path}.{}", p.key) };
                out.push(Problem { key, message: p.message });
            }
        }
        out
    }

    /// The friction law of `axis` from its friction effects, `None` if it has none.
    /// `stribeck.fc` unset takes `coulomb.fc`; a `lugre` effect supplies Fc, Fs, vs, δ itself.
    pub fn friction(&self, axis: Axis) -> Option<FrictionLaw> {
        let coulomb = self.get(EffectName::Coulomb, axis);
        let viscous = self.get(EffectName::Viscous, axis);
        let stribeck = self.get(EffectName::Stribeck, axis);
        let lugre = self.get(EffectName::Lugre, axis);
        if coulomb.is_none() && viscous.is_none() && stribeck.is_none() && lugre.is_none() {
            return None;
        }
        let fc0 = match coulomb.map(|e| &e.params) {
            Some(EffectParams::Coulomb(c)) => c.fc,
            _ => 0.0,
        };
        let mut law = StribeckLaw::coulomb(fc0);
        let mut bristles = None;
        if let Some(EffectParams::Viscous(v)) = viscous.map(|e| &e.params) {
            law.fv = v.fv;
        }
        if let Some(EffectParams::Stribeck(s)) = stribeck.map(|e| &e.params) {
            law = StribeckLaw { fc: s.fc.unwrap_or(fc0), fs: s.fs, vs: s.vs, delta: s.shape, fv: law.fv };
        }
        if let Some(EffectParams::Lugre(l)) = lugre.map(|e| &e.params) {
            law = StribeckLaw { fc: l.fc, fs: l.fs, vs: l.vs, delta: l.shape, fv: law.fv + l.sigma2 };
            bristles = Some([l.sigma0, l.sigma1]);
        }
        Some(FrictionLaw { steady: law, lugre: bristles })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_display_in_the_units_a_metrologist_reads() {
        assert_eq!(ParamUnit::Length.display(2.5368308714870326e-5), "25.37 µm");
        assert_eq!(ParamUnit::Length.display(0.010494734293211277), "10.49 mm");
        assert_eq!(ParamUnit::Length.display(1.25), "1.250 m");
        assert_eq!(ParamUnit::Angle.display(3.1e-6), "3.100 µrad");
        assert_eq!(ParamUnit::Velocity.display(0.0025), "2.500 mm/s");
        assert_eq!(ParamUnit::Time.display(312.1477), "312.1 s");
        assert_eq!(ParamUnit::ExpansionCoefficient.display(11.5e-6), "11.50 µm/(m·K)");
        assert_eq!(ParamUnit::Dimensionless.display(2.0), "2.000");
        assert_eq!(ParamUnit::Length.display(0.0), "0 µm");
        // Every catalogue parameter has a unit whose display names it (no bare SI number).
        for e in EffectName::ALL {
            for p in param_specs(e) {
                let text = p.unit.display(1e-3);
                assert!(text.contains(' ') || p.unit == ParamUnit::Dimensionless, "{}.{}: {text}", e.as_str(), p.key);
            }
        }
    }

    #[test]
    fn names_round_trip_through_strings_and_unknown_names_list_the_catalogue() {
        for n in EffectName::ALL {
            assert_eq!(n.as_str().parse::<EffectName>().unwrap(), n);
            assert_eq!(n.to_string(), n.as_str());
        }
        let e = "foo".parse::<EffectName>().unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("`foo`") && msg.contains("cyclic_lead") && msg.contains("lugre"));
        // ALL has no duplicate names.
        let mut names: Vec<&str> = EffectName::ALL.iter().map(|n| n.as_str()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), EffectName::ALL.len());
    }

    #[test]
    fn iso_symbols_of_the_x_axis_are_those_of_iso_230_1() {
        let s: Vec<String> = EffectName::ERROR_MOTIONS.iter().map(|n| n.iso230_symbol(Axis::X).unwrap()).collect();
        assert_eq!(s, ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"]);
        assert_eq!(EffectName::Backlash.iso230_symbol(Axis::X), None);
    }

    #[test]
    fn defaults_are_valid_and_every_default_matches_its_name() {
        for n in EffectName::ALL {
            let e = Effect::default_for(n, Axis::X);
            assert!(e.params.fits(n), "{n}");
            assert!(e.validate().is_empty(), "{n}: {:?}", e.validate());
        }
    }

    #[test]
    fn validation_names_the_key_path_of_each_out_of_range_value() {
        let mut set = EffectSet::default();
        set.insert(Effect {
            name: EffectName::Backlash,
            axis: Axis::X,
            params: EffectParams::Backlash(Backlash { value: -4e-6 }),
        });
        set.insert(Effect {
            name: EffectName::Resonance,
            axis: Axis::X,
            params: EffectParams::Resonance(Resonance { frequency: 120.0, damping: 1.0 }),
        });
        set.insert(Effect {
            name: EffectName::CyclicLead,
            axis: Axis::Y,
            params: EffectParams::CyclicLead(CyclicLead {
                period: 0.0,
                amplitude: 1e-6,
                phase: 0.0,
                harmonics: vec![],
            }),
        });
        let p = set.validate();
        assert_eq!(p.len(), 3, "{p:?}");
        assert_eq!(p[0].key, "effects.backlash.value");
        assert_eq!(p[0].message, "expected a length in metres ≥ 0, got -4e-6");
        assert_eq!(p[1].key, "effects.resonance.damping");
        assert!(p[1].message.contains("in [0, 1)"));
        assert_eq!(p[2].key, "effects.cyclic_lead.period");
        assert!(p[2].message.contains("> 0"));
    }

    #[test]
    fn duplicate_name_and_axis_is_a_problem_but_other_axes_are_not() {
        let mut set = EffectSet::default();
        set.effects.push(Effect::default_for(EffectName::Backlash, Axis::X));
        set.effects.push(Effect::default_for(EffectName::Backlash, Axis::Y));
        assert!(set.validate().is_empty());
        set.effects.push(Effect::default_for(EffectName::Backlash, Axis::X));
        let p = set.validate();
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].key, "effects.backlash[2]");
    }

    #[test]
    fn effect_equations_match_hand_worked_numbers() {
        // Thermal expansion: 11.5e-6 · 0.5 m · 2 K · (1 − e^−1) at t = τ.
        let th = ThermalExpansion { alpha: 11.5e-6, delta_t: 2.0, tau: 600.0 };
        let want = 11.5e-6 * 0.5 * 2.0 * (1.0 - (-1.0f64).exp());
        assert!((th.value(0.5, 600.0) - want).abs() < 1e-22);
        assert_eq!(th.value(0.5, -1.0), 0.0);
        // Cyclic lead at a quarter period: A.
        let cl = CyclicLead {
            period: 0.01,
            amplitude: 1.5e-6,
            phase: 0.0,
            harmonics: vec![LeadHarmonic { order: 2, amplitude: 0.5e-6, phase: 0.0 }],
        };
        // sin(π/2) = 1, sin(π) ≈ 1.2e-16: 1.5e-6 within 1e-18 (rounding of π).
        assert!((cl.value(0.0025) - 1.5e-6).abs() < 1e-18);
        // Stribeck: at v = vs, Fc + (Fs − Fc)/e, plus Fv·v.
        let mut set = EffectSet::default();
        set.insert(Effect {
            name: EffectName::Coulomb,
            axis: Axis::X,
            params: EffectParams::Coulomb(Coulomb { fc: 1.0 }),
        });
        set.insert(Effect {
            name: EffectName::Stribeck,
            axis: Axis::X,
            params: EffectParams::Stribeck(Stribeck { fc: None, fs: 1.5, vs: 1e-3, shape: 2.0 }),
        });
        set.insert(Effect {
            name: EffectName::Viscous,
            axis: Axis::X,
            params: EffectParams::Viscous(Viscous { fv: 0.4 }),
        });
        let law = set.friction(Axis::X).unwrap();
        let f = law.steady.force(-1e-3);
        let want = -(1.0 + 0.5 / std::f64::consts::E) - 0.4e-3;
        assert!((f - want).abs() < 1e-15, "{f} vs {want}");
        assert!(set.friction(Axis::Y).is_none());
    }

    #[test]
    fn scalars_and_set_address_parameters_by_key() {
        let mut p = EffectParams::default_for(EffectName::ServoLag);
        assert_eq!(p.scalars(EffectName::ServoLag), vec![("kv", 30.0)]);
        assert!(p.set("kp", 50.0));
        assert!(!p.set("nope", 1.0));
        assert_eq!(p.get("kp"), Some(50.0));
        assert_eq!(p.scalars(EffectName::ServoLag).len(), 2);
    }
}
