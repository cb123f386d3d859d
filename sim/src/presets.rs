//! Physically reasonable parameter sets for the bundled machines that reproduce a seed's measurement
//! from physics (no effect is injected as a signal).
//!
//! [`crawl_seed002`]: the X axis of `slide_column.urdf` (1236 kg moving mass) driven by a 16 mm ball
//! screw in closed loop on a linear scale, whose guideway friction makes it crawl at low feed the way
//! seed 002 (CN "基于内置编码器信号的机床爬行监测方法", stick-slip index from the built-in encoder)
//! reports: SSI = (s_max − s_min)/s_mean of the differentiated 2 kHz scale reading is 2.51 at 5 mm/min,
//! 1.07 at 20 mm/min and 0.15 at 80 mm/min.

use crate::axis_sim::{AxisTruth, GuideFriction};
use crate::drive::{BallScrewConfig, DriveConfig, FeedbackKind};
use crate::friction::StribeckLaw;
use crate::machine::AxisConfig;
use crate::sensors::{SensorKind, SensorSpec};
use crate::servo::ServoConfig;

/// Resolution of seed 002's linear scale, m: a 20 µm grating period (1 Vpp signal) interpolated
/// 4096 times by the counter card, q = 20e-6/4096 = 4.8828125e-9 m.
pub const SEED002_SCALE_RESOLUTION: f64 = 20e-6 / 4096.0;

/// An axis configuration (machine section) plus the injected physics (truth) and the sensor that
/// observes it: everything a crawl run of seed 002 needs besides the URDF.
#[derive(Clone, Debug, PartialEq)]
pub struct CrawlPreset {
    /// Machine section of the axis: drive (ball screw, closed loop on the linear scale) and servo.
    pub axis: AxisConfig,
    /// Injected physics: Stribeck guideway friction, no geometric errors.
    pub truth: AxisTruth,
    /// The linear scale read at 2 kHz, quantised to [`SEED002_SCALE_RESOLUTION`], named "scale".
    pub scale: SensorSpec,
}

/// Drive, servo, friction and scale of the slide_column X axis for seed 002's crawl test.
///
/// Mechanism (DESIGN.md §4 physics only): the axial mode of the ball-screw drive — rotor (equivalent
/// mass m_r = J·(2π/lead)² = 308 kg) against the 1236 kg body through the screw stiffness k = 2e8 N/m,
/// f = √(k·(1/m_r + 1/m))/2π ≈ 143 Hz (≈ 150 Hz in closed loop) — is damped by the screw's structural
/// damping (c = 2ζ·√(k·m) ≈ 1.0e5 N·s/m at ζ = 0.1) and by the servo. The guideway's Stribeck curve
/// F(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ) + Fv·v has a negative slope
/// dF/dv = Fv − (Fs − Fc)·δ/vs·u^(δ−1)·exp(−u^δ), u = v/vs, which acts as negative damping on that
/// mode. Where it outweighs the positive damping the steady crawl is unstable (Armstrong-Hélouvry 1991,
/// critical velocity): at 5 mm/min (u = 0.24) the mode grows into stick-slip that reaches zero velocity;
/// at 20 mm/min (u = 0.95, just below the critical feed) it settles on a limit cycle of ±58 % of the
/// feed that never sticks, because with δ = 1.5 the slope magnitude falls off on both sides of
/// u ≈ 0.5 so a larger swing averages less negative damping (supercritical Hopf branch); at 80 mm/min
/// (u = 3.8) the slope is 0.2 % of its peak and the crawl is smooth. With Fs = Fc (Coulomb + viscous)
/// there is no negative slope and no crawl at any feed.
///
/// Values and why they are realistic for a 1.2 t slide on four preloaded rolling blocks:
/// - Fc = 150 N (μ ≈ 0.012 on 12.1 kN normal load: rolling guides with seals and preload),
///   Fs = 280 N (Fs/Fc = 1.87), vs = 0.35 mm/s (21 mm/min), δ = 1.5 (Armstrong-Hélouvry's range 0.5…2),
///   Fv = 1000 N·s/m (500 N at 30 m/min rapid);
/// - ball screw: lead 16 mm, J = 0.002 kg·m² (motor + screw + coupling), k = 2e8 N/m (screw, nut and
///   bearings in series), ζ = 0.1; closed loop on the linear scale;
/// - servo: kp = 50 1/s (3 m/min/mm), velocity bandwidth 40 Hz on the motor encoder, integral corner
///   8 Hz, 5 kHz, velocity and acceleration feed-forward (the `ServoConfig` defaults);
/// - scale: seed 002's own, q = 20 µm/4096 = 4.88 nm, whose quantisation floor of SSI,
///   2q/(Δt·v) = 0.23 / 0.06 / 0.015 at 5 / 20 / 80 mm/min, stays far below the values reproduced.
///
/// Sensitivity (measured with `tests/crawl_seed002.rs`): the 20 mm/min value sits on the branch that
/// starts at the critical Fs; at this Fs its amplitude grows about 0.15 SSI per N of Fs, and for
/// Fs ≤ 278 N the 20 mm/min crawl is smooth again (SSI ≈ 0.06–0.26).
pub fn crawl_seed002() -> CrawlPreset {
    let servo = ServoConfig {
        kp: 50.0,
        velocity_bandwidth: 40.0,
        integral_corner: 8.0,
        resolution: SEED002_SCALE_RESOLUTION,
        ..ServoConfig::default()
    };
    let drive = DriveConfig::BallScrew(BallScrewConfig {
        lead: 0.016,
        rotor_inertia: 0.002,
        stiffness: 2e8,
        damping_ratio: 0.1,
        feedback: FeedbackKind::Linear,
    });
    let friction = GuideFriction::Stribeck(StribeckLaw { fc: 150.0, fs: 280.0, vs: 3.5e-4, delta: 1.5, fv: 1000.0 });
    let mut scale = SensorSpec::new("scale", SensorKind::EncoderLinear);
    scale.resolution = SEED002_SCALE_RESOLUTION;
    CrawlPreset {
        axis: AxisConfig { servo, drive, ..AxisConfig::default() },
        truth: AxisTruth { friction, ..AxisTruth::default() },
        scale,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed002_scale_resolution_is_20_um_over_4096() {
        // 20e-6 / 4096 = 4.8828125e-9 exactly in binary floating point (4096 is a power of two).
        assert_eq!(SEED002_SCALE_RESOLUTION, 4.8828125e-9);
    }

    #[test]
    fn preset_friction_is_a_valid_stribeck_curve() {
        let p = crawl_seed002();
        match &p.truth.friction {
            GuideFriction::Stribeck(s) => assert!(s.validate().is_ok()),
            other => panic!("expected Stribeck friction, got {other:?}"),
        }
    }
}
