//! One physics step of slide_column at dt = 1e-4 s, fast integrator against the rapier reference
//! (issue 15): the guideway bearings, the servo and the body update. Two configurations: a linear motor
//! with six error motions, the full drive (ball screw, backlash, LuGre friction), and the physical
//! study's physics (semi-closed ball screw, backlash, Coulomb friction, six error motions). The command
//! sweeps 0.1–0.9 m of the 1 m travel back and forth, so the step measured is the step of a procedure.
//!
//! Besides criterion's per-function timings, `interleaved_ratios` alternates short rounds of the fast
//! and the reference step and prints the median per-step times and their ratio measured in the same
//! run, so machine load affects both sides alike. When python's `mujoco` is importable, each round also
//! runs the MuJoCo anchor `benches/anchors/slide_column_mujoco.py` (the same body, mass and inertia, the
//! four blocks' stiffness and damping lumped about the centre of mass into five joint springs, a PD
//! position servo on x, `mj_step(nstep)`), and the ratios to it are printed; otherwise it says it skipped.
use criterion::{criterion_group, Criterion};
use std::time::Instant;
use vmt_sim::axis_sim::{AxisSim, AxisTruth, GuideFriction};
use vmt_sim::drive::{BallScrewConfig, DriveConfig, FeedbackKind};
use vmt_sim::friction::{LugreParams, StribeckLaw};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::machine::{AxisConfig, AxisModel, Fidelity};
use vmt_sim::motion::Command;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::parse_urdf;

include!("anchors/reference_step/cases_now.rs");

fn model(cfg: &AxisConfig, fidelity: Fidelity) -> AxisModel {
    let text = include_str!("../urdf/slide_column.urdf");
    AxisModel::build(&parse_urdf(text).unwrap(), &AxisConfig { fidelity, ..cfg.clone() }).unwrap()
}

/// The stretch of the 0..1 m travel the bench's command sweeps, m: the axis stays where the fast
/// engine's tabulated error motions apply (as in every procedure), however many steps a benchmark takes.
const SWEEP: (f64, f64) = (0.1, 0.9);

/// A running simulation stepping along a constant-feed command that reverses at the ends of [`SWEEP`]
/// (a triangle wave in position, feed `feed` m/s).
struct Runner<'a> {
    sim: AxisSim<'a>,
    x: f64,
    feed: f64,
    dt: f64,
}

impl<'a> Runner<'a> {
    /// A run of `m` under `truth` starting at rest at x = 0.2 m, commanded at `feed` m/s.
    fn new(m: &'a AxisModel, truth: &'a AxisTruth, feed: f64) -> Runner<'a> {
        Runner { sim: AxisSim::new(m, truth, 0.2), x: 0.2, feed, dt: m.dt }
    }

    fn step(&mut self) {
        self.x += self.feed * self.dt;
        if !(SWEEP.0..=SWEEP.1).contains(&self.x) {
            self.feed = -self.feed;
        }
        self.sim.step(Command { pos: self.x, vel: self.feed, acc: 0.0 });
    }
}

fn step(c: &mut Criterion) {
    let mut g = c.benchmark_group("slide_column step (dt = 1e-4 s)");
    for case in cases() {
        for fidelity in [Fidelity::Fast, Fidelity::Reference] {
            let m = model(&case.cfg, fidelity);
            let mut r = Runner::new(&m, &case.truth, case.feed);
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
        let mut fast = Runner::new(&mf, &case.truth, case.feed);
        let mut reference = Runner::new(&mr, &case.truth, case.feed);
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
        if let Some(mj) = (matches!(case.cfg.drive, DriveConfig::LinearMotor) && mujoco_available()).then(|| {
            let args = mujoco_args(&mf, case.feed);
            // Rounds of its own, alternating with the fast engine so the same load hits both.
            let (mut tf2, mut tm) = (Vec::new(), Vec::new());
            for _ in 0..ROUNDS {
                let t0 = Instant::now();
                for _ in 0..STEPS {
                    fast.step();
                }
                tf2.push(t0.elapsed().as_secs_f64() / STEPS as f64 * 1e6);
                tm.extend(run_mujoco(&args));
            }
            (median(tf2), median(tm))
        }) {
            let (f2, m) = mj;
            println!(
                "interleaved {}: fast {f2:.3} µs/step, MuJoCo anchor {m:.3} µs/step (medians of {ROUNDS} rounds); MuJoCo/fast = {:.2}",
                case.name,
                m / f2
            );
        } else if matches!(case.cfg.drive, DriveConfig::LinearMotor) {
            println!("MuJoCo anchor skipped: python3 cannot import mujoco (pip install mujoco)");
        }
    }
}

/// True when `python3 -c "import mujoco"` succeeds.
fn mujoco_available() -> bool {
    std::process::Command::new("python3").args(["-c", "import mujoco"]).output().is_ok_and(|o| o.status.success())
}

/// The anchor's command line: steps, then the body and its lumped springs from vmt's model (mass,
/// principal inertia taken as the inertia tensor's diagonal, Σk_y, Σk_z, rotational stiffnesses
/// Σ(k_y·z² + k_z·y²), Σk_z·x², Σk_y·x² about the centre of mass and the same for damping), the
/// servo as a PD (kp = m·2π·f_v·kp_pos N/m, kv = m·2π·f_v N·s/m), the feed and the step.
fn mujoco_args(m: &AxisModel, feed: f64) -> Vec<String> {
    let rel: Vec<_> = m.blocks.iter().map(|b| *b - m.com).collect();
    let sum = |f: &dyn Fn(&(f64, f64, f64)) -> f64| rel.iter().map(|r| f(&(r.x, r.y, r.z))).sum::<f64>();
    let (ky, kz, cy, cz) = (m.k_y, m.k_z, m.c_y, m.c_z);
    let kv = m.mass * std::f64::consts::TAU * m.servo.velocity_bandwidth;
    let v = [
        m.mass,
        m.inertia.x_axis.x,
        m.inertia.y_axis.y,
        m.inertia.z_axis.z,
        ky * rel.len() as f64,
        kz * rel.len() as f64,
        sum(&|r| ky * r.2 * r.2 + kz * r.1 * r.1),
        sum(&|r| kz * r.0 * r.0),
        sum(&|r| ky * r.0 * r.0),
        cy * rel.len() as f64,
        cz * rel.len() as f64,
        sum(&|r| cy * r.2 * r.2 + cz * r.1 * r.1),
        sum(&|r| cz * r.0 * r.0),
        sum(&|r| cy * r.0 * r.0),
        kv * m.servo.kp,
        kv,
        feed,
        m.dt,
    ];
    std::iter::once("200000".to_string()).chain(v.iter().map(|x| format!("{x:e}"))).collect()
}

/// One round of the MuJoCo anchor: its median µs/step, None if it failed.
fn run_mujoco(args: &[String]) -> Option<f64> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/anchors/slide_column_mujoco.py");
    let o = std::process::Command::new("python3").arg(script).args(args).output().ok()?;
    let text = String::from_utf8_lossy(&o.stdout);
    text.lines().find_map(|l| l.strip_prefix("us_per_step=")).and_then(|v| v.trim().parse().ok())
}

/// Runs `n` steps of case `case` (an index into [`cases`]) with the engine `fidelity` and prints the
/// final position: a fixed amount of work for instruction counts, which do not depend on the machine's
/// load (`VMT_STEP_COUNT=0,reference,100000 valgrind --tool=callgrind target/release/deps/sim_step-…`;
/// the per-step count is the difference of two runs of different `n`, divided by their difference).
fn count_steps(spec: &str) -> Result<(), String> {
    let parts: Vec<&str> = spec.split(',').collect();
    let [case, fidelity, n] = parts[..] else {
        return Err(format!("VMT_STEP_COUNT={spec}: expected CASE,FIDELITY,STEPS (e.g. 0,reference,100000)"));
    };
    let all = cases();
    let case = case.parse::<usize>().ok().and_then(|i| all.get(i)).ok_or(format!(
        "VMT_STEP_COUNT={spec}: CASE must be an index below {} ({})",
        all.len(),
        all.iter().map(|c| c.name).collect::<Vec<_>>().join("; ")
    ))?;
    let fidelity = match fidelity {
        "fast" => Fidelity::Fast,
        "reference" => Fidelity::Reference,
        other => return Err(format!("VMT_STEP_COUNT={spec}: FIDELITY {other:?} is not fast or reference")),
    };
    let n: u64 = n.parse().map_err(|_| format!("VMT_STEP_COUNT={spec}: STEPS {n:?} is not a count"))?;
    let m = model(&case.cfg, fidelity);
    let mut r = Runner::new(&m, &case.truth, case.feed);
    for _ in 0..n {
        r.step();
    }
    let s = r.sim.sample(Command { pos: r.x, vel: r.feed, acc: 0.0 });
    println!("{}, {fidelity:?}: {n} steps, final position {:?} m, rotation {:?} rad", case.name, s.pos, s.rot);
    Ok(())
}

criterion_group!(benches, step, interleaved_ratios);

/// The criterion benchmarks, or with `VMT_STEP_COUNT` set, [`count_steps`] alone.
fn main() {
    if let Ok(spec) = std::env::var("VMT_STEP_COUNT") {
        if let Err(e) = count_steps(&spec) {
            eprintln!("{e}");
            std::process::exit(2);
        }
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
