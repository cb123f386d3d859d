// The API of vmt-sim at 59b65eb (main when issue 15 was filed): rapier the only engine, LugreParams
// with flat Stribeck fields (σ2 = Fv), StribeckParams for Coulomb (Fs = Fc, vs = 1, δ = 2, Fv = 0).
use vmt_sim::axis_sim::{AxisSim, AxisTruth, GuideFriction};
use vmt_sim::drive::{BallScrewConfig, DriveConfig, FeedbackKind};
use vmt_sim::friction::{LugreParams, StribeckParams};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::machine::{AxisConfig, AxisModel};
use vmt_sim::motion::Command;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::parse_urdf;

/// A named configuration: model config, truth, feed (m/s) (cases_now.rs's, for the API of 59b65eb).
struct Case {
    name: &'static str,
    cfg: AxisConfig,
    truth: AxisTruth,
    feed: f64,
}

fn six() -> AxisTruth {
    let h = |a: f64, w: f64| Harmonic { amplitude: a, wavelength: w, phase: 0.0 };
    AxisTruth::geometric(ErrorMotions {
        positioning: Profile::poly(vec![0.0, 2e-5]),
        straightness_y: Profile::harmonics(vec![h(2e-6, 0.5)]),
        straightness_z: Profile::harmonics(vec![h(2e-6, 0.3)]),
        roll: Profile::harmonics(vec![h(1e-5, 0.7)]),
        pitch: Profile::harmonics(vec![h(1e-5, 0.9)]),
        yaw: Profile::harmonics(vec![h(1e-5, 1.1)]),
    })
}

fn cases() -> Vec<Case> {
    let lugre = LugreParams { sigma0: 1e8, sigma1: 2e4, sigma2: 800.0, fc: 150.0, fs: 250.0, vs: 1e-3, delta: 2.0 };
    let coulomb = StribeckParams { fc: 100.0, fs: 100.0, vs: 1.0, delta: 2.0, fv: 0.0 };
    let semi = BallScrewConfig { feedback: FeedbackKind::Rotary, ..BallScrewConfig::default() };
    vec![
        Case { name: "linear motor, six error motions", cfg: AxisConfig::default(), truth: six(), feed: 0.1 },
        Case {
            name: "ball screw + backlash + LuGre",
            cfg: AxisConfig { drive: DriveConfig::BallScrew(BallScrewConfig::default()), ..AxisConfig::default() },
            truth: AxisTruth { backlash: 4e-6, friction: GuideFriction::LuGre(lugre), ..AxisTruth::default() },
            feed: 0.01,
        },
        Case {
            name: "semi-closed ball screw + backlash + Coulomb, six error motions",
            cfg: AxisConfig { drive: DriveConfig::BallScrew(semi), ..AxisConfig::default() },
            truth: AxisTruth { backlash: 4e-6, friction: GuideFriction::Stribeck(coulomb), ..six() },
            feed: 0.1,
        },
    ]
}

fn model(text: &str, cfg: &AxisConfig, fast: bool) -> Option<AxisModel> {
    (!fast).then(|| AxisModel::build(&parse_urdf(text).unwrap(), cfg).unwrap())
}
