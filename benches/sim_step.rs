//! One physics step of slide_column at dt = 1e-4 s, fast integrator against the rapier reference
//! (issue 15): the guideway bearings, the servo and the body update. Two configurations: a linear motor
//! with six error motions, and the full drive (ball screw, backlash, LuGre friction).
//!
//! Besides criterion's per-function timings, `interleaved_ratios` alternates short rounds of the fast
//! and the reference step and prints the median per-step times and their ratio measured in the same
//! run, so machine load affects both sides alike. (No MuJoCo anchor yet: python `mujoco` is not
//! installed on the build machine.)
use criterion::{criterion_group, criterion_main, Criterion};
use std::time::Instant;
use vmt_sim::axis_sim::{AxisSim, AxisTruth, GuideFriction};
use vmt_sim::drive::{BallScrewConfig, DriveConfig};
use vmt_sim::friction::LugreParams;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::machine::{AxisConfig, AxisModel, Fidelity};
use vmt_sim::motion::Command;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::parse_urdf;

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
    let lugre = LugreParams { sigma0: 1e8, sigma1: 2e4, sigma2: 800.0, fc: 150.0, fs: 250.0, vs: 1e-3, delta: 2.0 };
    vec![
        Case { name: "linear motor, six error motions", cfg: AxisConfig::default(), truth: six, feed: 0.1 },
        Case {
            name: "ball screw + backlash + LuGre",
            cfg: AxisConfig { drive: DriveConfig::BallScrew(BallScrewConfig::default()), ..AxisConfig::default() },
            truth: AxisTruth { backlash: 4e-6, friction: GuideFriction::LuGre(lugre), ..AxisTruth::default() },
            feed: 0.01,
        },
    ]
}

fn model(cfg: &AxisConfig, fidelity: Fidelity) -> AxisModel {
    let text = include_str!("../urdf/slide_column.urdf");
    AxisModel::build(&parse_urdf(text).unwrap(), &AxisConfig { fidelity, ..cfg.clone() }).unwrap()
}

/// A running simulation stepping along a constant-feed command.
struct Runner<'a> {
    sim: AxisSim<'a>,
    x: f64,
    feed: f64,
    dt: f64,
}

impl Runner<'_> {
    fn step(&mut self) {
        self.x += self.feed * self.dt;
        self.sim.step(Command { pos: self.x, vel: self.feed, acc: 0.0 });
    }
}

fn step(c: &mut Criterion) {
    let mut g = c.benchmark_group("slide_column step (dt = 1e-4 s)");
    for case in cases() {
        for fidelity in [Fidelity::Fast, Fidelity::Reference] {
            let m = model(&case.cfg, fidelity);
            let mut r = Runner { sim: AxisSim::new(&m, &case.truth, 0.2), x: 0.2, feed: case.feed, dt: m.dt };
            g.bench_function(format!("{}, {fidelity:?}", case.name), |b| b.iter(|| r.step()));
        }
    }
    g.finish();
}

/// Median of a sample.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Alternating rounds of 20 000 steps of the fast and reference engines; median µs/step of each and
/// their ratio, printed (ratios within one run: the load of a shared machine hits both alike).
fn interleaved_ratios(_c: &mut Criterion) {
    const ROUNDS: usize = 15;
    const STEPS: usize = 20_000;
    for case in cases() {
        let (mf, mr) = (model(&case.cfg, Fidelity::Fast), model(&case.cfg, Fidelity::Reference));
        let mut fast = Runner { sim: AxisSim::new(&mf, &case.truth, 0.2), x: 0.2, feed: case.feed, dt: mf.dt };
        let mut reference = Runner { sim: AxisSim::new(&mr, &case.truth, 0.2), x: 0.2, feed: case.feed, dt: mr.dt };
        let (mut tf, mut tr) = (Vec::new(), Vec::new());
        for _ in 0..ROUNDS {
            for (r, t) in [(&mut fast, &mut tf), (&mut reference, &mut tr)] {
                let t0 = Instant::now();
                for _ in 0..STEPS {
                    r.step();
                }
                t.push(t0.elapsed().as_secs_f64() / STEPS as f64 * 1e6);
            }
        }
        let (f, r) = (median(tf), median(tr));
        println!(
            "interleaved {}: fast {f:.3} µs/step, reference (rapier) {r:.3} µs/step (medians of {ROUNDS} rounds); reference/fast = {:.2}",
            case.name,
            r / f
        );
    }
}

criterion_group!(benches, step, interleaved_ratios);
criterion_main!(benches);
