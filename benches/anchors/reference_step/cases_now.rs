// The cases of benches/sim_step.rs in the API of vmt-sim from ce7e26e on (fidelity selectable, LugreParams
// { steady: StribeckLaw }): included by benches/sim_step.rs and by the step server of
// reference_step_ab.py (api_now.rs), so both step the same configurations. The including file imports
// the types.
/// A named configuration: model config, truth, feed (m/s).
struct Case {
    name: &'static str,
    cfg: AxisConfig,
    truth: AxisTruth,
    feed: f64,
}

fn cases() -> Vec<Case> {
    let h = |a: f64, w: f64| Harmonic { amplitude: a, wavelength: w, phase: 0.0 };
    let six = AxisTruth::geometric(ErrorMotions {
        positioning: Profile::poly(vec![0.0, 2e-5]),
        straightness_y: Profile::harmonics(vec![h(2e-6, 0.5)]),
        straightness_z: Profile::harmonics(vec![h(2e-6, 0.3)]),
        roll: Profile::harmonics(vec![h(1e-5, 0.7)]),
        pitch: Profile::harmonics(vec![h(1e-5, 0.9)]),
        yaw: Profile::harmonics(vec![h(1e-5, 1.1)]),
    });
    let lugre = LugreParams {
        sigma0: 1e8,
        sigma1: 2e4,
        steady: StribeckLaw { fc: 150.0, fs: 250.0, vs: 1e-3, delta: 2.0, fv: 800.0 },
    };
    let semi = BallScrewConfig { feedback: FeedbackKind::Rotary, ..BallScrewConfig::default() };
    vec![
        Case { name: "linear motor, six error motions", cfg: AxisConfig::default(), truth: six.clone(), feed: 0.1 },
        Case {
            name: "ball screw + backlash + LuGre",
            cfg: AxisConfig { drive: DriveConfig::BallScrew(BallScrewConfig::default()), ..AxisConfig::default() },
            truth: AxisTruth { backlash: 4e-6, friction: GuideFriction::LuGre(lugre), ..AxisTruth::default() },
            feed: 0.01,
        },
        // The physics of the physical study (benches/study_physical.toml): semi-closed loop on the motor
        // encoder, backlash, Coulomb guideway friction and six error motions.
        Case {
            name: "semi-closed ball screw + backlash + Coulomb, six error motions",
            cfg: AxisConfig { drive: DriveConfig::BallScrew(semi), ..AxisConfig::default() },
            truth: AxisTruth { backlash: 4e-6, friction: GuideFriction::Stribeck(StribeckLaw::coulomb(100.0)), ..six },
            feed: 0.1,
        },
    ]
}
