//! One physics step of slide_column at dt = 1e-4 s: the guideway bearings, the servo and rapier's step.
use criterion::{criterion_group, criterion_main, Criterion};
use vmt_sim::axis_sim::AxisSim;
use vmt_sim::axis_sim::AxisTruth;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::machine::{AxisConfig, AxisModel};
use vmt_sim::motion::Command;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::parse_urdf;

fn step(c: &mut Criterion) {
    let text = include_str!("../urdf/slide_column.urdf");
    let model = AxisModel::build(&parse_urdf(text).unwrap(), &AxisConfig::default()).unwrap();
    let h = |a: f64, w: f64| Harmonic { amplitude: a, wavelength: w, phase: 0.0 };
    let errors = AxisTruth::geometric(ErrorMotions {
        positioning: Profile::poly(vec![0.0, 2e-5]),
        straightness_y: Profile::harmonics(vec![h(2e-6, 0.5)]),
        straightness_z: Profile::harmonics(vec![h(2e-6, 0.3)]),
        roll: Profile::harmonics(vec![h(1e-5, 0.7)]),
        pitch: Profile::harmonics(vec![h(1e-5, 0.9)]),
        yaw: Profile::harmonics(vec![h(1e-5, 1.1)]),
    });
    let mut sim = AxisSim::new(&model, &errors, 0.2);
    let mut x = 0.2;
    c.bench_function("slide_column step (dt = 1e-4 s, six error motions)", |b| {
        b.iter(|| {
            x += 0.1 * model.dt;
            sim.step(Command { pos: x, vel: 0.1, acc: 0.0 });
        })
    });
}

/// The same step with the full drive: ball screw (rotor, axial stiffness, backlash) and LuGre friction.
fn step_full_drive(c: &mut Criterion) {
    use vmt_sim::axis_sim::GuideFriction;
    use vmt_sim::drive::{BallScrewConfig, DriveConfig};
    use vmt_sim::friction::LugreParams;
    let text = include_str!("../urdf/slide_column.urdf");
    let cfg = AxisConfig { drive: DriveConfig::BallScrew(BallScrewConfig::default()), ..AxisConfig::default() };
    let model = AxisModel::build(&parse_urdf(text).unwrap(), &cfg).unwrap();
    let lugre = LugreParams { sigma0: 1e8, sigma1: 2e4, sigma2: 800.0, fc: 150.0, fs: 250.0, vs: 1e-3, delta: 2.0 };
    let truth = AxisTruth { backlash: 4e-6, friction: GuideFriction::LuGre(lugre), ..AxisTruth::default() };
    let mut sim = AxisSim::new(&model, &truth, 0.2);
    let mut x = 0.2;
    c.bench_function("slide_column step, ball screw + backlash + LuGre", |b| {
        b.iter(|| {
            x += 0.01 * model.dt;
            sim.step(Command { pos: x, vel: 0.01, acc: 0.0 });
        })
    });
}

criterion_group!(benches, step, step_full_drive);
criterion_main!(benches);
