//! From the named effects of a truth (FORMAT.md §2, `effects`) to the physics of one axis: where each
//! effect acts in the simulator. Geometric error motions shape the guideway; scale error, interpolation
//! error, thermal expansion and drift distort the feedback chain; cyclic lead error and backlash live in
//! the screw; friction on the guideway; a resonance is a column mode; servo lag sets the loop gains;
//! accelerometer bias drift is a sensor property. Gravity through tilt and Abbe offsets need no
//! parameter: they follow from the geometry.

use crate::axis_sim::{AxisTruth, GuideFriction, StructuralMode};
use crate::effects::{EffectName, EffectParams, EffectSet, FrictionLaw};
use crate::friction::LugreParams;
use crate::geometry::ErrorMotions;
use crate::machine::AxisModel;
use crate::profile::{Harmonic, Profile, Term};
use crate::Axis;

/// What a truth does to one axis beyond `AxisTruth`: changes to the machine model and to sensors.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Adjustments {
    /// servo_lag: the position-loop gain K_v (1/s) without velocity feed-forward.
    pub servo_kv: Option<f64>,
    /// accel_bias_drift: bias random walk of every accelerometer, m/s²/√s.
    pub accel_bias_drift: Option<f64>,
}

/// Why a truth cannot act on an axis (the caller adds the file and key).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TruthError {
    /// A screw effect on an axis without a ball screw.
    #[error("effect `{effect}` on axis {axis} needs a ball-screw drive ([axis.drive] kind = \"ball_screw\")")]
    NeedsBallScrew {
        /// The effect (`cyclic_lead`, `backlash`).
        effect: EffectName,
        /// The axis.
        axis: Axis,
    },
    /// A Stribeck curve rising from rest: Fs < Fc (refused, not raised to Fc).
    #[error(
        "friction on axis {axis} ({}): static friction fs = {} N is below the Coulomb level fc = {} N; expected fs ≥ fc",
        if *.lugre { "lugre" } else { "stribeck (fc from coulomb unless given)" },
        crate::effects::fmt_num(*.fs),
        crate::effects::fmt_num(*.fc)
    )]
    StaticBelowCoulomb {
        /// The axis.
        axis: Axis,
        /// True when the law comes from a `lugre` effect, false from `stribeck`/`coulomb`.
        lugre: bool,
        /// Static friction Fs, N.
        fs: f64,
        /// Coulomb friction Fc, N.
        fc: f64,
    },
}

/// Builds the physics of axis `axis` from an effect set. `model` gives the moving body's height for
/// the resonance mode shape. Errors name the effect that cannot act on this machine.
pub fn axis_physics(set: &EffectSet, axis: Axis, model: &AxisModel) -> Result<(AxisTruth, Adjustments), TruthError> {
    let motion = |n: EffectName| set.error_motion(n, axis).cloned().unwrap_or_default();
    let mut truth = AxisTruth {
        motions: ErrorMotions {
            positioning: motion(EffectName::Positioning),
            straightness_y: motion(EffectName::StraightnessY),
            straightness_z: motion(EffectName::StraightnessZ),
            roll: motion(EffectName::Roll),
            pitch: motion(EffectName::Pitch),
            yaw: motion(EffectName::Yaw),
        },
        ..Default::default()
    };
    let mut adj = Adjustments::default();
    let is_screw = matches!(model.drive, crate::drive::DriveConfig::BallScrew(_));
    let mut along: Vec<Term> = Vec::new();
    for e in set.effects.iter().filter(|e| e.axis == axis) {
        let need_screw = |effect: EffectName| {
            if is_screw {
                Ok(())
            } else {
                Err(TruthError::NeedsBallScrew { effect, axis })
            }
        };
        match &e.params {
            EffectParams::ScaleError(s) => along.push(Term::Poly(vec![0.0, s.value])),
            EffectParams::InterpolationError(i) => along.push(Term::Harmonics(vec![Harmonic {
                amplitude: i.amplitude,
                wavelength: i.period,
                phase: i.phase,
            }])),
            EffectParams::ThermalExpansion(t) => truth.feedback.thermal_expansion = Some(t.clone()),
            EffectParams::ThermalDrift(d) => truth.feedback.thermal_drift = Some(d.clone()),
            EffectParams::CyclicLead(c) => {
                need_screw(EffectName::CyclicLead)?;
                let mut h = vec![Harmonic { amplitude: c.amplitude, wavelength: c.period, phase: c.phase }];
                h.extend(c.harmonics.iter().map(|k| Harmonic {
                    amplitude: k.amplitude,
                    wavelength: c.period / k.order as f64,
                    phase: k.phase,
                }));
                truth.lead_error = Profile::harmonics(h);
            }
            EffectParams::Backlash(b) => {
                need_screw(EffectName::Backlash)?;
                truth.backlash = b.value;
            }
            EffectParams::Resonance(r) => {
                let height = model.links.iter().map(|(_, f)| model.body_to_axis(f.translation).z).fold(0.0, f64::max);
                truth.mode =
                    Some(StructuralMode { frequency: r.frequency, damping: r.damping, height: height.max(0.1) })
            }
            EffectParams::ServoLag(s) => adj.servo_kv = Some(s.kv),
            EffectParams::AccelBiasDrift(d) => adj.accel_bias_drift = Some(d.rate),
            // Acting elsewhere: the error motions shape the guideway (above), squareness joins the axes
            // of a chain (`crate::chain`), the friction effects combine into one law (below) and
            // gravity through tilt follows from the angles.
            EffectParams::ErrorMotion(_)
            | EffectParams::Squareness(_)
            | EffectParams::Coulomb(_)
            | EffectParams::Viscous(_)
            | EffectParams::Stribeck(_)
            | EffectParams::Lugre(_)
            | EffectParams::GravityTilt => {}
        }
    }
    if !along.is_empty() {
        truth.feedback.along = Profile { terms: along };
    }
    truth.friction = match set.friction(axis) {
        None => GuideFriction::None,
        // The Stribeck curve falls from Fs at rest to Fc in sliding: Fs < Fc is no friction law (refused,
        // not raised to Fc behind the user's back).
        Some(FrictionLaw { steady: law, lugre }) if law.fs < law.fc => {
            return Err(TruthError::StaticBelowCoulomb { axis, lugre: lugre.is_some(), fs: law.fs, fc: law.fc });
        }
        Some(FrictionLaw { steady: law, lugre }) => match lugre {
            Some([sigma0, sigma1]) => GuideFriction::LuGre(LugreParams { sigma0, sigma1, steady: law }),
            None => GuideFriction::Stribeck(law),
        },
    };
    Ok((truth, adj))
}

impl Adjustments {
    /// Applies the servo-lag gain to a machine model: K_p = K_v, no velocity or acceleration feed-forward.
    pub fn apply(&self, model: &mut AxisModel) {
        if let Some(kv) = self.servo_kv {
            model.servo.kp = kv;
            model.servo.velocity_feed_forward = false;
            model.servo.acceleration_feed_forward = false;
        }
    }
}
